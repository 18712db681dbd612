"""Scaling cases of the benchmark, each measured in a fresh subprocess: time and peak memory.

:func:`smooth_views` generates the synthetic views; :func:`bench_scaling` and
:func:`bench_coil100` run each case (explicit, streaming exact, subspace or randomized fit, or the
whole build with flow and synthesis) through ``python -m torch_eigview.apps.bench --worker
SPEC`` so that its peak resident set (:class:`_PeakRss`) is its own.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import torch
import torch.nn.functional as F

from torch_eigview.decomposition.streaming import CHUNK_VIEWS
from torch_eigview.scale.thread_policy import eigen_flops, for_products, threads

__all__ = ["bench_coil100", "bench_scaling", "run_case", "smooth_views"]


def smooth_views(obj: int, n_views: int = 41, channels: int = 1, size: int = 128) -> torch.Tensor:
    """(n_views, channels, size, size) float32 random smooth views of synthetic object ``obj``.

    A random low-resolution texture (seeded by ``obj``) is upsampled bicubically to
    ``size`` × (``size`` + ``n_views``) and view t is the window starting at column t: the
    object slides by one pixel per view, so consecutive views are correlated like a
    turntable sequence. Deterministic: the same call gives the same views.
    """
    gen = torch.Generator().manual_seed(1_000_003 * obj + 17)
    low = torch.rand(1, channels, 8, 8 + max(1, (8 * n_views) // size), generator=gen)
    wide = F.interpolate(low, size=(size, size + n_views), mode="bicubic", align_corners=False)[0]
    cols = torch.arange(size)[None, :] + torch.arange(n_views)[:, None]  # (T, size)
    return wide[:, :, cols].permute(2, 0, 1, 3).contiguous().clamp_(0, 1)


def _rss_bytes(pid: str = "self") -> int:
    """The current resident set of a process (Linux /proc; 0 elsewhere or once it is gone)."""
    try:
        with open(f"/proc/{pid}/statm") as fh:
            return int(fh.read().split()[1]) * _PAGE
    except OSError:  # not Linux, or the process just ended
        return 0


def _children_rss_bytes() -> int:
    """Summed resident sets of this process's child processes and theirs (worker pools).

    Shared pages (libraries, shared-memory tensors) count once per process: an upper bound.
    """
    total, todo, seen = 0, [str(os.getpid())], set()
    while todo:
        pid = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tasks:
            try:
                with open(f"/proc/{pid}/task/{tid}/children") as fh:
                    kids = fh.read().split()
            except OSError:
                continue
            for kid in kids:
                if kid not in seen:
                    seen.add(kid)
                    total += _rss_bytes(kid)
                    todo.append(kid)
    return total


_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


class _PeakRss:
    """Peak resident set during a ``with`` block, minus the resident set just before it.

    A thread samples /proc/self/statm every millisecond; ``ru_maxrss`` (the process's
    high-water mark) is used as well when the block raised it, so a short peak between two
    samples is not missed then. The baseline is the *current* resident set before the block,
    not the earlier high-water mark: imports and warm-ups peak higher than they end, and a
    ``ru_maxrss`` delta reads 0 for a block that stays below that earlier peak.
    """

    def __enter__(self) -> _PeakRss:
        import resource
        import threading

        self._resource = resource
        self.baseline = _rss_bytes()
        self._max_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        self.peak = self.baseline
        self.children_peak = 0
        self._stop = threading.Event()

        def sample() -> None:
            n = 0
            while not self._stop.wait(0.001):
                self.peak = max(self.peak, _rss_bytes())
                n += 1
                if n % 20 == 0:  # child processes: every 20 ms (walking /proc costs more)
                    self.children_peak = max(self.children_peak, _children_rss_bytes())

        self._thread = threading.Thread(target=sample, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, _rss_bytes())
        max_after = self._resource.getrusage(self._resource.RUSAGE_SELF).ru_maxrss * 1024
        if max_after > self._max_before:
            self.peak = max(self.peak, max_after)

    @property
    def mib(self) -> float:
        return (self.peak - self.baseline) / 2**20

    @property
    def children_mib(self) -> float:
        """Peak summed resident set of child processes (0 without any)."""
        return self.children_peak / 2**20


def run_case(spec: dict[str, Any]) -> dict[str, Any]:
    """One measurement in this (fresh) process: seconds and extra peak RSS of one fit."""
    from torch_eigview.decomposition.eigenspace import Eigenspace
    from torch_eigview.decomposition.streaming import StreamingEigenspace

    n_obj, size, ch, k, kind = spec["objects"], spec["size"], spec["channels"], spec["k"], spec["kind"]

    def source() -> Any:
        return (smooth_views(o, 41, ch, size) for o in range(n_obj))

    after_imports = _rss_bytes()
    warm = torch.cat([smooth_views(o, 41, ch, 16) for o in range(2)])  # loads BLAS, LAPACK, pools
    Eigenspace(5).fit(warm)
    StreamingEigenspace(5, method="randomized").fit(warm)
    del warm
    passes, n_threads = 1, torch.get_num_threads()
    extra: dict[str, Any] = {}
    n_views, n_features = n_obj * 41, ch * size * size
    flops = eigen_flops(n_views, n_features)
    with _PeakRss() as peak:
        t0 = time.perf_counter()
        if kind == "pipeline":
            # The whole build: per object flow + 41 synthesized views (two seeds 5 px apart),
            # stored once in a disk cache, then the eigenspace from the cache by the default
            # method (the exact Gram by panels).
            # Objects go to ``workers`` processes or threads (one torch thread each), results
            # come back in order.
            from torch_eigview.scale.parallel import synthesize_objects
            from torch_eigview.scale.view_cache import ViewCache

            seeds = (smooth_views(o, 6, ch, size)[[0, 5]] for o in range(n_obj))
            with ViewCache() as cache:
                kind = spec.get("worker_kind", "process")
                # Thread workers run one torch thread each, as under the commands' policy.
                with threads(1) if kind == "thread" else contextlib.nullcontext():
                    stream = synthesize_objects(
                        seeds, 5.0, list(range(-20, 21)), workers=spec.get("workers", 0), kind=kind
                    )
                    for synth in stream:
                        cache.append(synth.views)
                extra["synthesis_s"] = time.perf_counter() - t0
                with for_products(flops) as n_threads:
                    space = StreamingEigenspace(k, max_views=spec["max_views"]).fit(cache)
                extra["method"] = space.method_
                passes = space.n_passes_
        elif kind == "explicit":
            with for_products(flops) as n_threads:
                Eigenspace(k).fit(torch.cat(list(source())))
        else:
            with for_products(flops) as n_threads:
                space = StreamingEigenspace(k, method=kind, max_views=spec["max_views"]).fit(source)
            passes = space.n_passes_
            extra["method"] = space.method_
        seconds = time.perf_counter() - t0
    return {
        **spec,
        **extra,
        "seconds": seconds,
        "peak_mib": peak.mib,
        "workers_peak_mib": peak.children_mib,
        "passes": passes,
        "eigen_threads": n_threads,
        "baseline_mib": peak.baseline / 2**20,
        "imports_mib": after_imports / 2**20,
    }


def _measure(spec: dict[str, Any]) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "torch_eigview.apps.bench", "--worker", json.dumps(spec)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"benchmark worker {spec} failed:\n{done.stderr[-2000:]}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    n = result["objects"] * 41
    features = result["channels"] * result["size"] ** 2
    result["data_matrix_mib"] = n * features * 4 / 2**20
    # The exact fit's square matrix: the P×P Gram (P < N) or the N×N scatter.
    result["gram_mib"] = min(n, features) ** 2 * 8 / 2**20
    result["block_mib"] = 41 * features * 4 / 2**20
    # Views a streaming fit holds at once: the exact Gram path a panel plus a chunk of later
    # views, the scatter path a chunk of N/2 views, the randomized one a block.
    max_views = result["max_views"]
    # (the method that ran: a subspace fit that handed over to the exact path held its views).
    method = result.get("method", result["kind"])
    if method == "exact":
        held = min(max_views, n) + min(CHUNK_VIEWS, max_views, n) if n < features else features // 2
    elif method == "subspace":
        held = min(CHUNK_VIEWS, n)  # a chunk of centred views
    else:
        held = 41 if result["kind"] == "randomized" else 0
    result["panel_mib"] = held * features * 4 / 2**20
    return result


def bench_scaling(
    sizes: Sequence[int], objects: Sequence[int], size_objects: int, objects_size: int, panel: int
) -> dict[str, Any]:
    """Time and peak memory of explicit / streaming exact / randomized fits, each in a fresh process.

    ``by_size``: ``size_objects`` objects (41 views each) at growing image sides; ``by_objects``:
    growing numbers of objects at ``objects_size`` x ``objects_size`` (the Gram path when
    N > P: memory should follow a panel of ``panel`` views and a chunk plus P², and past
    P = N a chunk plus N², never P·N).
    """
    by_size = [
        _measure(dict(kind=kind, objects=size_objects, size=s, channels=1, k=15, max_views=panel))
        for s in sizes
        for kind in ("explicit", "exact", "randomized")
    ]
    by_objects = [
        _measure(dict(kind=kind, objects=n, size=objects_size, channels=1, k=15, max_views=panel))
        for n in objects
        for kind in ("explicit", "exact", "randomized")
    ]
    return {"by_size": by_size, "by_objects": by_objects}


def bench_coil100(n_objects: int, panel: int, explicit: bool) -> list[dict[str, Any]]:
    """COIL-100-sized builds: the eigen step alone (explicit / exact / subspace / randomized
    on generated views) and ``pipeline``, the whole build with flow and synthesis."""
    from torch_eigview.scale.parallel import available_cpus

    kinds = (
        ("explicit", "exact", "subspace", "randomized") if explicit else ("exact", "subspace", "randomized")
    )
    spec = dict(objects=n_objects, size=128, channels=3, k=15, max_views=panel)
    rows = [_measure(dict(spec, kind=k)) for k in kinds]
    # The whole build in this process (torch's threads), over one process per CPU and over
    # one thread per CPU (the commands' default).
    for workers, worker_kind in ((0, "process"), (available_cpus(), "process"), (available_cpus(), "thread")):
        rows.append(_measure(dict(spec, kind="pipeline", workers=workers, worker_kind=worker_kind)))
    return rows
