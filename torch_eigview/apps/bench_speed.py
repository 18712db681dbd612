"""Benchmark sections of the speed work: per-stage times, the thread policy under load, CUDA.

``stages``: seconds per stage of a COIL run (correspondence, maps, warp, eigen,
recognition; the maps and the warp measured apart on each object's first seed pair).
``threads``: the same ``eigview coil`` run as a subprocess with the default policy, one
thread and two threads, on the machine as it is ("quiet") and beside a CPU-bound
neighbour the benchmark starts itself (one spinning process per CPU, each ending by
itself after a bounded time and killed after the measurement), and beside them a
reference job of plain matrix products on one and two threads, whose slow-down is what
the scheduler leaves any CPU-bound job; every run is bounded by a timeout. ``cuda``: views synthesized per second and the COIL-100-sized build end to
end on the GPU; without one it says "not measured: no GPU" and runs the same code on the
CPU at a small size, so that the one command is known to work.

All figures are wall-clock seconds of this machine as it is: on a machine that other
processes load, ratios taken in the same run are the meaningful figures.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Any

import torch

from torch_eigview.apps.bench_scaling import smooth_views

__all__ = ["bench_cuda", "bench_stages", "bench_threads", "cpu_neighbour"]

_THETAS = list(range(-20, 21))


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _clock(device: torch.device) -> float:
    _sync(device)
    return time.perf_counter()


# ---------------------------------------------------------------------------- stages
def bench_stages(root: str, objects: Sequence[int], alpha: float = 10.0) -> dict[str, Any]:
    """Per-stage seconds of ``eigview coil`` on ``objects`` of the COIL folder ``root``.

    ``correspondence``, ``synthesis``, ``eigen`` and ``recognition`` are the experiment's
    own times; ``maps`` and ``warp`` split the synthesis of each object's first seed pair
    (``NovelViewWarp.maps`` and ``apply_maps``, measured again apart).
    """
    from torch_eigview.datasets.coil import CoilFolder
    from torch_eigview.evaluation.coil import CoilExperiment
    from torch_eigview.synthesis import pair_geometry
    from torch_eigview.warp.novel_view import NovelViewWarp

    folder = CoilFolder(root)
    result = CoilExperiment(alpha=alpha, objects=list(objects)).run(folder)
    maps_s = warp_s = 0.0
    for obj in objects:
        seeds = folder.images(obj, [0.0, alpha])
        geo = pair_geometry(seeds, alpha)[0]
        warp = NovelViewWarp(alpha, elevation=geo.elevation)
        t0 = time.perf_counter()
        maps = warp.maps(geo.correspondence, _THETAS)
        t1 = time.perf_counter()
        warp.apply_maps(maps, seeds[:, None])
        maps_s, warp_s = maps_s + t1 - t0, warp_s + time.perf_counter() - t1
    seconds = dict(result.seconds)
    return {
        "objects": len(objects),
        "alpha": alpha,
        "threads": torch.get_num_threads(),
        "accuracy": result.accuracy,
        "seconds": seconds,
        "maps_s": maps_s,
        "warp_s": warp_s,
    }


# ---------------------------------------------------------------------------- threads
_SPIN = "import time\nend = time.monotonic() + {limit}\nwhile time.monotonic() < end:\n    pass\n"


@contextmanager
def cpu_neighbour(n_procs: int, limit_s: float) -> Iterator[list[subprocess.Popen[bytes]]]:
    """``n_procs`` processes spinning on the CPU for at most ``limit_s`` seconds each.

    They end by themselves after ``limit_s`` (so a killed benchmark leaves nothing
    behind for long), and are killed on exit from the ``with`` block.
    """
    procs = [
        subprocess.Popen([sys.executable, "-c", _SPIN.format(limit=float(limit_s))]) for _ in range(n_procs)
    ]
    try:
        time.sleep(0.2)  # let them reach the spinning loop
        yield procs
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()


def _run_command(args: list[str], timeout_s: float) -> float | None:
    """Wall seconds of ``python -m torch_eigview ARGS`` (None when it ran past ``timeout_s``)."""
    return _run_python(["-m", "torch_eigview", *args], timeout_s, f"eigview {' '.join(args)}")


def _run_python(argv: list[str], timeout_s: float, name: str) -> float | None:
    """Wall seconds of ``python ARGV`` (None when it ran past ``timeout_s``); ``name`` in its error."""
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    t0 = time.perf_counter()
    try:
        done = subprocess.run(
            [sys.executable, *argv],
            timeout=timeout_s,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
    except subprocess.TimeoutExpired:
        return None
    if done.returncode:
        raise RuntimeError(f"{name} failed ({done.returncode}): {done.stderr.strip()[-500:]}")
    return time.perf_counter() - t0


# A fixed amount of CPU-bound work (matrix products) on N torch threads: the reference of
# what the CPU scheduler leaves any job beside the neighbour, whatever its thread policy.
_REFERENCE = (
    "import torch\ntorch.set_num_threads({threads})\n"
    "a = torch.randn(512, 512, generator=torch.Generator().manual_seed(0))\n"
    "for _ in range({iters}):\n    a = (a @ a).div_(a.norm())\n"
)


def _quiet_and_loaded(
    setting: str, run: Callable[[], float | None], n_procs: int, timeout_s: float
) -> dict[str, Any]:
    """One row of the threads table: ``run`` on the machine as it is, then beside the neighbour."""
    quiet = run()
    with cpu_neighbour(n_procs, timeout_s + 5):
        loaded = run()
    ratio = None if quiet is None or loaded is None else loaded / quiet
    return {"setting": setting, "quiet_s": quiet, "loaded_s": loaded, "loaded_over_quiet": ratio}


def _reference_rows(n_procs: int, timeout_s: float, iters: int) -> list[dict[str, Any]]:
    """The reference job on one and on two threads, quiet then beside the neighbour."""
    rows = []
    for n_threads in (1, 2):
        argv = ["-c", _REFERENCE.format(threads=n_threads, iters=iters)]
        name = f"reference: {n_threads} thread{'s' if n_threads > 1 else ''}"
        rows.append(_quiet_and_loaded(name, partial(_run_python, argv, timeout_s, name), n_procs, timeout_s))
    return rows


def _command(root: str | None, objects: str) -> list[str]:
    """A COIL run when the images are there, else the synthetic demo (no figure)."""
    if root is not None and Path(root).is_dir():
        return ["coil", "--root", root, "--alpha", "10", "--objects", objects, "--quiet"]
    return ["demo", "--size", "48", "--png", "", "--quiet"]


def bench_threads(
    root: str | None,
    objects: str = "1-4",
    timeout_s: float = 120.0,
    neighbour_procs: int | None = None,
    reference_iters: int = 400,
) -> dict[str, Any]:
    """The thread policy against one and two threads, quiet and beside a CPU-bound neighbour.

    Each setting runs the same command as a subprocess (``OMP_NUM_THREADS`` unset, so
    only ``--threads`` decides); quiet and loaded runs are interleaved per setting. A
    reference job, ``reference_iters`` products of 512 × 512 matrices on one and on two
    torch threads, runs the same way: its loaded/quiet ratio is what the CPU scheduler
    allows any CPU-bound job beside this neighbour (with the neighbour on every CPU, about
    1.5 for one busy thread and 2 for two), the floor the command's ratio is read against.

    Returns:
        ``{"command", "rows": [{setting, quiet_s, loaded_s, loaded_over_quiet}],
        "references": [the same for the reference job], ...}``; a time is None where
        the run passed ``timeout_s``.
    """
    from torch_eigview.scale.parallel import available_cpus

    base = _command(root, objects)
    # The policy's workers (one thread per CPU, one object each) against one process thread
    # doing everything, with one and with two intra-op threads.
    one = ["--workers", "0"] if base[0] == "coil" else []
    settings = {
        "policy (default)": [],
        f"{' '.join(one)} --threads 1".strip(): [*one, "--threads", "1"],
        f"{' '.join(one)} --threads 2".strip(): [*one, "--threads", "2"],
    }
    n_procs = neighbour_procs or available_cpus()
    rows = [
        _quiet_and_loaded(name, partial(_run_command, [*base, *extra], timeout_s), n_procs, timeout_s)
        for name, extra in settings.items()
    ]
    return {
        "command": " ".join(base),
        "neighbour_procs": n_procs,
        "timeout_s": timeout_s,
        "rows": rows,
        "references": _reference_rows(n_procs, timeout_s, reference_iters),
    }


def report_threads(t: dict[str, Any]) -> None:
    """Prints :func:`bench_threads`'s table and whether the policy stays within 1.3× of the
    best setting quiet and loaded, and within 1.5× of its quiet time when loaded."""
    print(
        f"\n== threads: `eigview {t['command']}`, quiet and beside {t['neighbour_procs']} spinning processes"
    )
    print(f"  {'setting':<26} {'quiet s':>9} {'loaded s':>9} {'loaded/quiet':>13}")

    def fmt(v: float | None, spec: str) -> str:
        return f"> {t['timeout_s']:.0f}" if v is None else format(v, spec)

    for r in [*t["rows"], *t.get("references", [])]:
        print(
            f"  {r['setting']:<26} {fmt(r['quiet_s'], '9.2f'):>9} {fmt(r['loaded_s'], '9.2f'):>9} "
            f"{fmt(r['loaded_over_quiet'], '13.2f'):>13}"
        )
    policy = t["rows"][0]
    for key in ("quiet_s", "loaded_s"):
        times = [r[key] for r in t["rows"] if r[key] is not None]
        if policy[key] is not None and times:
            share = policy[key] / min(times)
            print(
                f"  policy / best ({key[:-2]}): {share:.2f} (target <= 1.3: {'met' if share <= 1.3 else 'NOT met'})"
            )
    ratio = policy["loaded_over_quiet"]
    if ratio is not None:
        print(f"  policy loaded / quiet: {ratio:.2f} (target <= 1.5: {'met' if ratio <= 1.5 else 'NOT met'})")
    floor = {r["setting"]: r["loaded_over_quiet"] for r in t.get("references", [])}
    if floor and all(v is not None for v in floor.values()):
        print(
            "  the scheduler's floor beside this neighbour, the reference job's loaded / quiet: "
            + ", ".join(f"{v:.2f} ({k.removeprefix('reference: ')})" for k, v in floor.items())
        )


# ---------------------------------------------------------------------------- cuda
def _warp_rate(device: torch.device, n_objects: int, size: int, repeats: int = 3) -> float:
    """Views per second of maps + warp for ``n_objects`` objects × 41 angles in one batch."""
    import math

    from torch_eigview.geometry.correspondence import correspondence_from_disparity
    from torch_eigview.warp.novel_view import NovelViewWarp

    ramp = torch.sin(torch.linspace(0, math.pi, size))[None, :].expand(size, size)
    disp = torch.stack([-(1.0 + 0.1 * o) * ramp for o in range(n_objects)]).to(device)
    corr = correspondence_from_disparity(disp)
    seeds = torch.stack([smooth_views(o, 6, 3, size)[[0, 5]] for o in range(n_objects)], 1).to(device)
    warp = NovelViewWarp(5.0, elevation=10.0)
    best = math.inf
    for _ in range(repeats + 1):  # the first call warms up
        t0 = _clock(device)
        warp.apply_maps(warp.maps(corr, _THETAS), seeds)
        best = min(best, _clock(device) - t0)
    return n_objects * len(_THETAS) / best


def _build(device: torch.device, n_objects: int, size: int) -> tuple[float, torch.Tensor]:
    """The COIL-100-sized build end to end on ``device``: correspondence (the default guided
    flow: the row matcher and TV-L1, every object's pair and both directions in one batch,
    on the device), synthesis and the eigenspace (k = 15) of ``n_objects`` synthetic
    objects; (seconds, components)."""
    from torch_eigview.decomposition.eigenspace import Eigenspace
    from torch_eigview.synthesis import SynthesisOptions, object_geometries, synthesize_views

    seeds = [smooth_views(o, 6, 3, size)[[0, 5]].to(device) for o in range(n_objects)]
    options = SynthesisOptions()
    t0 = _clock(device)
    geometry = object_geometries(seeds, 5.0, options)
    views = [
        synthesize_views(s, 5.0, _THETAS, options, g).views for s, g in zip(seeds, geometry, strict=True)
    ]
    x = torch.cat(views).flatten(1)
    space = Eigenspace(15).fit(x)
    seconds = _clock(device) - t0
    return seconds, space.components_.detach().to("cpu", torch.float64)


def _principal_angle(a: torch.Tensor, b: torch.Tensor) -> float:
    qa, qb = torch.linalg.qr(a.T).Q, torch.linalg.qr(b.T).Q
    return float(torch.arccos(torch.linalg.svdvals(qa.T @ qb).clamp(max=1.0).min()))


def bench_cuda(quick: bool) -> dict[str, Any]:
    """Views per second and the COIL-100-sized build on CUDA, with the principal angle of its
    eigenspace to the CPU build's; without a GPU the CPU fallback at a small size."""
    if torch.cuda.is_available():
        device, n_objects, size = torch.device("cuda"), (10 if quick else 100), 128
    else:
        device, n_objects, size = torch.device("cpu"), 3, 64
    out: dict[str, Any] = {"device": str(device), "objects": n_objects, "size": size}
    out["views_per_s"] = _warp_rate(device, n_objects, size)
    out["build_s"], comps = _build(device, n_objects, size)
    if device.type == "cuda":
        cpu_s, cpu_comps = _build(torch.device("cpu"), n_objects, size)
        out["cpu_build_s"] = cpu_s
        out["angle_to_cpu_rad"] = _principal_angle(comps, cpu_comps)
    return out


def report_cuda(c: dict[str, Any]) -> None:
    """Prints :func:`bench_cuda`'s figures (and says plainly when no GPU measured them)."""
    what = f"{c['objects']} objects x 41 views x 3x{c['size']}x{c['size']}"
    if c["device"] == "cpu":
        print(f"\n== cuda: not measured: no GPU. CPU fallback of the same code ({what}):")
    else:
        print(f"\n== cuda: {what} on {torch.cuda.get_device_name()}")
    print(f"  maps + warp: {c['views_per_s']:.0f} views/s")
    print(
        f"  build end to end (the guided flow, synthesis and eigenspace on {c['device']}): {c['build_s']:.2f} s"
    )
    if "angle_to_cpu_rad" in c:
        ok = c["objects"] == 100 and c["build_s"] < 3 and c["angle_to_cpu_rad"] < 1e-4
        print(
            f"  CPU build {c['cpu_build_s']:.2f} s; largest principal angle to it {c['angle_to_cpu_rad']:.1e} rad "
            f"(target: under 3 s for 100 objects and < 1e-4 rad: {'met' if ok else 'NOT met'})"
        )


def run_sections(sections: Sequence[str], results: dict[str, Any], root: str | None, quick: bool) -> None:
    """Runs and prints the ``stages``, ``threads`` and ``cuda`` sections named in ``sections``."""
    objects = [1, 2] if quick else [1, 2, 3, 4]
    if "stages" in sections:
        if root is None or not Path(root).is_dir():
            print(f"\n== stages: not measured: no COIL folder at {root}")
        else:
            s = results["stages"] = bench_stages(root, objects)
            sec = s["seconds"]
            print(
                f"\n== stages: eigview coil --alpha 10 on {s['objects']} COIL objects, {s['threads']} thread(s)"
            )
            for key in ("correspondence", "synthesis", "eigen", "recognition", "total"):
                print(f"  {key:<15} {sec.get(key, float('nan')):8.3f} s")
            print(f"  of the synthesis, first seed pair: maps {s['maps_s']:.3f} s, warp {s['warp_s']:.3f} s")
    if "threads" in sections:
        t = results["threads"] = bench_threads(
            root, "1-2" if quick else "1-4", 60.0 if quick else 180.0, reference_iters=100 if quick else 400
        )
        report_threads(t)
    if "cuda" in sections:
        c = results["cuda"] = bench_cuda(quick)
        report_cuda(c)
