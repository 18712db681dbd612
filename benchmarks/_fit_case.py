"""One eigenspace fit measured in a fresh process: its seconds and its extra peak memory.

:func:`measure` runs :func:`run_case` in a new interpreter (``python benchmarks/_fit_case.py
SPEC``) so that the peak resident set it reports is the fit's own. Torch's CPU allocator
keeps no statistics and ``tracemalloc`` does not see torch's allocations, so the peak comes
from the operating system: the resident set sampled every millisecond during the fit
(/proc/self/statm, and ``ru_maxrss`` when the fit raised it) minus the resident set just
before it, after the imports and a tiny warm-up fit. Views generated on the fly count.

A case (``spec``) names ``kind`` (``explicit``: :class:`Eigenspace` on the stacked views;
``exact``, ``subspace``, ``randomized``: :class:`StreamingEigenspace` on a stream of
objects; ``pipeline``: the whole build, flow and synthesis into a :class:`ViewCache`, then
the eigenspace from it), ``objects`` (41 views each), ``size``, ``channels``, ``k`` and
``max_views`` (the exact path's panel); ``pipeline`` takes ``workers`` and ``worker_kind``.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/_fit_case.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import torch

from benchmarks._views import smooth_views
from torch_eigview.decomposition import Eigenspace, StreamingEigenspace
from torch_eigview.decomposition.streaming import CHUNK_VIEWS
from torch_eigview.scale import ViewCache, synthesize_objects, threads
from torch_eigview.scale.thread_policy import eigen_flops, for_products

__all__ = ["PeakRss", "measure", "run_case"]

_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


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


class PeakRss:
    """Peak resident set during a ``with`` block, minus the resident set just before it.

    A thread samples /proc/self/statm every millisecond; ``ru_maxrss`` (the process's
    high-water mark) is used as well when the block raised it, so a short peak between two
    samples is not missed then. The baseline is the *current* resident set before the block,
    not the earlier high-water mark: imports and warm-ups peak higher than they end, and a
    ``ru_maxrss`` delta reads 0 for a block that stays below that earlier peak.
    """

    def __enter__(self) -> PeakRss:
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
    n_obj, size, ch, k, kind = spec["objects"], spec["size"], spec["channels"], spec["k"], spec["kind"]

    def source() -> Any:
        return (smooth_views(o, 41, ch, size) for o in range(n_obj))

    after_imports = _rss_bytes()
    warm = torch.cat([smooth_views(o, 41, ch, 16) for o in range(2)])  # loads BLAS, LAPACK, pools
    Eigenspace(5).fit(warm)
    StreamingEigenspace(5, solver="randomized").fit(warm)
    del warm
    passes, n_threads = 1, torch.get_num_threads()
    extra: dict[str, Any] = {}
    flops = eigen_flops(n_obj * 41, ch * size * size)
    with PeakRss() as peak:
        t0 = time.perf_counter()
        if kind == "pipeline":
            # The whole build: per object flow + 41 synthesized views (two seeds 5 px apart),
            # stored once in a disk cache, then the eigenspace from the cache by the default
            # method (the exact Gram by panels). Objects go to ``workers`` processes or
            # threads (one torch thread each), results come back in order.
            seeds = (smooth_views(o, 6, ch, size)[[0, 5]] for o in range(n_obj))
            with ViewCache() as cache:
                worker_kind = spec.get("worker_kind", "process")
                # Thread workers run one torch thread each, as under the commands' policy.
                with threads(1) if worker_kind == "thread" else contextlib.nullcontext():
                    stream = synthesize_objects(
                        seeds, 5.0, list(range(-20, 21)), workers=spec.get("workers", 0), kind=worker_kind
                    )
                    for synth in stream:
                        cache.append(synth.views)
                extra["synthesis_s"] = time.perf_counter() - t0
                with for_products(flops) as n_threads:
                    space = StreamingEigenspace(k, max_views=spec["max_views"]).fit(cache)
                extra["method"] = space.solver_
                passes = space.n_passes_
        elif kind == "explicit":
            with for_products(flops) as n_threads:
                Eigenspace(k).fit(torch.cat(list(source())))
        else:
            with for_products(flops) as n_threads:
                space = StreamingEigenspace(k, solver=kind, max_views=spec["max_views"]).fit(source)
            passes = space.n_passes_
            extra["method"] = space.solver_
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


def measure(spec: dict[str, Any]) -> dict[str, Any]:
    """:func:`run_case` in a fresh interpreter under the commands' thread policy, with the
    memory the fit's data and its streaming parts take by their sizes."""
    cmd = [sys.executable, str(Path(__file__).resolve()), json.dumps(spec)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"benchmark case {spec} failed:\n{done.stderr[-2000:]}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    n = result["objects"] * 41
    features = result["channels"] * result["size"] ** 2
    result["data_matrix_mib"] = n * features * 4 / 2**20
    # The exact fit's square matrix: the P×P Gram (P < N) or the N×N scatter.
    result["gram_mib"] = min(n, features) ** 2 * 8 / 2**20
    result["block_mib"] = 41 * features * 4 / 2**20
    # Views a streaming fit holds at once: the exact Gram path a panel plus a chunk of later
    # views, the scatter path a chunk of N/2 views, the randomized one a block (the method
    # that ran: a subspace fit that handed over to the exact path held its views).
    max_views = result["max_views"]
    method = result.get("method", result["kind"])
    if method == "exact":
        held = min(max_views, n) + min(CHUNK_VIEWS, max_views, n) if n < features else features // 2
    elif method == "subspace":
        held = min(CHUNK_VIEWS, n)  # a chunk of centred views
    else:
        held = 41 if result["kind"] == "randomized" else 0
    result["held_mib"] = held * features * 4 / 2**20
    return result


if __name__ == "__main__":
    with threads(None):  # the commands' policy, as the old ``--worker`` entry ran it
        print(json.dumps(run_case(json.loads(sys.argv[1]))))
