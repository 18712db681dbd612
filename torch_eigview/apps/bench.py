"""Benchmarks: the warp, the eigen step, GEMM throughput, scaling and COIL-100-sized builds.

Run ``python -m torch_eigview.apps.bench`` (``--quick`` for a small run, ``--json FILE``,
``--png FILE``, ``--sections warp eigen gemm scaling coil100 stages threads cuda``,
``--threads N``; the last three sections are in :mod:`torch_eigview.apps.bench_speed`). Times are the best of a
few repeats (``time.perf_counter``), printed with ratios to our method.

Peak memory: torch's CPU allocator keeps no statistics and ``tracemalloc`` does not see
torch's allocations, so every memory figure comes from a fresh subprocess per
measurement (only imports and a tiny warm-up fit before it): the peak resident set during
the measured work (/proc/self/statm sampled every millisecond, and ``ru_maxrss`` when the
work raised it) minus the resident set just before it. The delta is the extra peak memory
of the measured step, views generated on the fly included.

The sparse G·C product and the per-view skimage loop of the warp section are only run up
to ``_WARP_SLOW_MAX`` pixels a side (they take minutes beyond); larger rows say "skipped".
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch

from torch_eigview.apps.bench_plot import plot_results
from torch_eigview.apps.bench_scaling import bench_coil100, bench_scaling, run_case, smooth_views
from torch_eigview.apps.bench_speed import run_sections
from torch_eigview.apps.cli_args import threads_arg
from torch_eigview.files import check_outputs, write_json
from torch_eigview.scale.thread_policy import threads

__all__ = ["main", "smooth_views"]

# Relative to the working folder, as the README runs it from the checkout.
_DEFAULT_ROOT = "../shared/data/coil-20-proc"
_SECTIONS = ("warp", "eigen", "gemm", "scaling", "coil100", "stages", "threads", "cuda")
_WARP_SLOW_MAX = 128  # largest side for the sparse G·C and skimage warp comparisons


def _best(fn: Callable[[], object], repeats: int) -> float:
    fn()  # warm-up: first-call allocations, kernel selection
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


# ---------------------------------------------------------------------------- warp
def _warp_row(size: int, n_views: int, thetas: torch.Tensor, repeats: int) -> dict[str, Any]:
    from skimage.transform import warp as sk_warp

    from torch_eigview.geometry.correspondence import correspondence_from_disparity
    from torch_eigview.warp.novel_view import NovelViewWarp
    from torch_eigview.warp.operator import SparseViewOperator

    seeds = smooth_views(0, 2, 1, size)  # (2, 1, H, W)
    disparity = -2.0 * torch.sin(torch.linspace(0, math.pi, size))[None, :].expand(size, size).contiguous()
    corr = correspondence_from_disparity(disparity)
    warp = NovelViewWarp(5.0, elevation=0.0)
    maps = warp.maps(corr, thetas)
    t_kornia = _best(lambda: NovelViewWarp.apply_maps(maps, seeds[:, None]), repeats)
    if size > _WARP_SLOW_MAX:
        return dict(size=size, views=n_views, kornia_s=t_kornia, skipped=True)
    t_build = _best(lambda: SparseViewOperator.from_maps(seeds, maps), max(1, repeats // 2))
    op = SparseViewOperator.from_maps(seeds, maps)
    t_sparse = _best(op.views, repeats)

    src_x = torch.where(maps.weight > 0, maps.src_x, -10.0).nan_to_num(-10.0).double().numpy()
    weight = maps.weight.double().numpy()
    images = seeds[:, 0].double().numpy()
    grid_rows = np.broadcast_to(np.arange(size, dtype=np.float64)[:, None], (size, size))

    def skimage_loop() -> np.ndarray:
        out = np.zeros((n_views, size, size))
        for t in range(n_views):
            for s in range(2):
                coords = np.stack([grid_rows, src_x[s, 0, t]])  # (row, col) of the source pixel
                out[t] += weight[s, 0, t] * sk_warp(images[s], coords, order=1, mode="constant", cval=0.0)
        return out

    t_skimage = _best(skimage_loop, max(1, repeats // 2))
    ref = NovelViewWarp.apply_maps(maps, seeds[:, None])[0, :, 0].double()
    err_sparse = float((op.views()[:, 0].double() - ref).abs().max())
    err_skimage = float((torch.from_numpy(skimage_loop()) - ref).abs().max())
    return dict(
        size=size,
        views=n_views,
        kornia_s=t_kornia,
        sparse_views_s=t_sparse,
        sparse_build_s=t_build,
        skimage_loop_s=t_skimage,
        max_diff_sparse=err_sparse,
        max_diff_skimage=err_skimage,
    )


def bench_warp(sizes: Sequence[int], n_views: int, repeats: int) -> list[dict[str, Any]]:
    """Warping P views: kornia grid sampling vs the torch.sparse G·C product vs skimage per view."""
    thetas = torch.linspace(-20, 20, n_views, dtype=torch.float64)
    return [_warp_row(size, n_views, thetas, repeats) for size in sizes]


# ---------------------------------------------------------------------------- eigen
def coil20_matrix(root: str | None, quick: bool) -> tuple[torch.Tensor, str]:
    """The (820, 16384) nvs data matrix of COIL-20 (α = 5, −20°..20°), unit-norm rows, or a stand-in."""
    from pathlib import Path

    if root is not None and Path(root).is_dir() and not quick:
        from torch_eigview.datasets.coil import CoilFolder
        from torch_eigview.synthesis import synthesize_views

        folder = CoilFolder(root)
        thetas = list(range(-20, 21))
        views = [synthesize_views(folder.images(o, [0.0, 5.0]), 5.0, thetas).views for o in folder.objects]
        x, what = torch.cat(views).flatten(1), f"COIL-20 nvs views from {root}"
    else:
        n_obj, size = (5, 64) if quick else (20, 128)
        x = torch.cat([smooth_views(o, 41, 1, size) for o in range(n_obj)]).flatten(1)
        what = "synthetic smooth views (COIL-20 absent or --quick)"
    return (x / x.norm(dim=1, keepdim=True)).contiguous(), what


def _angle(a: np.ndarray | torch.Tensor, b: torch.Tensor) -> float:
    a = torch.as_tensor(np.asarray(a), dtype=torch.float64)
    q = torch.linalg.qr(a.T).Q
    s = torch.linalg.svdvals(q.T @ b.double().T).clamp(max=1.0)
    return float(torch.arccos(s.min()))


def bench_eigen(x: torch.Tensor, k: int, repeats: int) -> dict[str, Any]:
    """Ours (Gram) vs sklearn PCA full/randomized vs torch.pca_lowrank(q=k+10, niter=2)."""
    from sklearn.decomposition import PCA

    from torch_eigview.decomposition.eigenspace import Eigenspace
    from torch_eigview.decomposition.linalg import gram

    xn = x.numpy()
    ours = Eigenspace(k).fit(x)
    xc = x - x.mean(0)
    out: dict[str, Any] = {"P": x.shape[0], "N": x.shape[1], "k": k}
    out["ours_s"] = _best(lambda: Eigenspace(k).fit(x), repeats)
    out["ours_gram_only_s"] = _best(lambda: gram(xc), repeats)
    out["sklearn_full_s"] = _best(lambda: PCA(k, svd_solver="full").fit(xn), max(1, repeats // 3))
    out["sklearn_randomized_s"] = _best(
        lambda: PCA(k, svd_solver="randomized", random_state=0).fit(xn), repeats
    )
    out["pca_lowrank_s"] = _best(lambda: torch.pca_lowrank(x, q=k + 10, niter=2), repeats)
    ref = ours.components_
    out["angle_sklearn_full"] = _angle(PCA(k, svd_solver="full").fit(xn).components_, ref)
    out["angle_sklearn_randomized"] = _angle(
        PCA(k, svd_solver="randomized", random_state=0).fit(xn).components_, ref
    )
    out["angle_pca_lowrank"] = _angle(torch.pca_lowrank(x, q=k + 10, niter=2)[2][:, :k].T, ref)
    out["speedup_vs_sklearn_full"] = out["sklearn_full_s"] / out["ours_s"]
    out["ratio_to_pca_lowrank"] = out["ours_s"] / out["pca_lowrank_s"]
    return out


def bench_gemm(n: int, repeats: int) -> dict[str, Any]:
    a, b = torch.randn(n, n), torch.randn(n, n)
    t = _best(lambda: torch.mm(a, b), repeats)
    return {"n": n, "seconds": t, "gflops": 2 * n**3 / t / 1e9, "threads": torch.get_num_threads()}


# ---------------------------------------------------------------------------- report
def _table(rows: list[dict[str, Any]], cols: Sequence[tuple[str, str, str]]) -> str:
    head = "  ".join(f"{title:>{len(title) if len(title) > 9 else 9}}" for title, _, _ in cols)
    lines = [head]
    for r in rows:
        cells = []
        for title, key, fmt in cols:
            width = len(title) if len(title) > 9 else 9
            cells.append(f"{format(r[key], fmt):>{width}}" if key in r else " " * width)
        lines.append("  ".join(cells))
    return "\n".join(lines)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m torch_eigview.apps.bench", description=__doc__.splitlines()[0]
    )
    p.add_argument("--quick", action="store_true", help="small sizes only (about a minute)")
    p.add_argument("--json", default=None, metavar="FILE", help="write all figures here")
    p.add_argument("--png", default=None, metavar="FILE", help="plot of the scaling here")
    p.add_argument("--sections", nargs="+", choices=_SECTIONS, default=list(_SECTIONS))
    p.add_argument(
        "--root",
        default=None,
        help=f"COIL-20 folder for the eigen section (default {_DEFAULT_ROOT}, a synthetic stand-in where absent)",
    )
    p.add_argument("--threads", type=threads_arg, default=None, metavar="N", help="torch threads (default 1)")
    p.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    return p


_WARP_COLS = [
    ("size", "size", "d"),
    ("kornia s", "kornia_s", ".4f"),
    ("sparse G·C s", "sparse_views_s", ".4f"),
    ("(build G,C s)", "sparse_build_s", ".4f"),
    ("skimage s", "skimage_loop_s", ".4f"),
    ("sparse/kornia", "sparse_x", ".2f"),
    ("skimage/kornia", "skimage_x", ".1f"),
    ("max|sparse-k|", "max_diff_sparse", ".1e"),
    ("max|skimage-k|", "max_diff_skimage", ".1e"),
]
_SCALING_COLS = [
    ("kind", "kind", "s"),
    ("objects", "objects", "d"),
    ("size", "size", "d"),
    ("seconds", "seconds", ".3f"),
    ("peak MiB", "peak_mib", ".1f"),
    ("passes", "passes", "d"),
    ("P·N·4 MiB", "data_matrix_mib", ".1f"),
    ("min(P,N)²·8 MiB", "gram_mib", ".1f"),
    ("held views MiB", "panel_mib", ".1f"),
]
_PANEL = 205  # views per panel of the exact Gram path (5 objects): memory is a panel plus P²


def _met(ok: bool) -> str:
    return "met" if ok else "NOT met"


def _section_gemm(results: dict[str, Any], quick: bool, reps: int) -> None:
    g = results["gemm"] = bench_gemm(1024 if quick else 2048, reps)
    print(f"\n== GEMM: torch.mm {g['n']}x{g['n']} float32: {g['seconds']:.4f} s, {g['gflops']:.1f} GFLOP/s")


def _section_warp(results: dict[str, Any], quick: bool, reps: int) -> None:
    w = results["warp"] = bench_warp([32, 64] if quick else [32, 64, 128, 256], 41, reps)
    for r in w:
        if not r.get("skipped"):
            r["sparse_x"] = r["sparse_views_s"] / r["kornia_s"]
            r["skimage_x"] = r["skimage_loop_s"] / r["kornia_s"]
    print("\n== warp 41 views (2 seed views blended): seconds, and ratio to kornia")
    print(_table(w, _WARP_COLS))
    for r in w:
        if r.get("skipped"):
            print(
                f"  {r['size']}x{r['size']}: sparse G·C and skimage loop skipped (too slow: minutes "
                f"beyond {_WARP_SLOW_MAX}x{_WARP_SLOW_MAX}); kornia only"
            )


def _section_eigen(results: dict[str, Any], root: str | None, quick: bool, reps: int) -> None:
    x, what = coil20_matrix(root, quick)
    e = results["eigen"] = bench_eigen(x, 15, reps)
    e["data"] = what
    gemm = results["gemm"]["gflops"]
    flops = 2.0 * e["N"] * e["P"] ** 2  # the Gram matrix as a GEMM counts it
    e["achieved_gflops"] = flops / e["ours_s"] / 1e9
    e["gemm_fraction"] = e["achieved_gflops"] / gemm
    print(f"\n== eigen step on the {e['P']} x {e['N']} data matrix, k = 15 ({what})")
    for key, label, angle in (
        ("ours_s", "ours (Eigenspace, gram)", None),
        ("sklearn_full_s", 'sklearn PCA svd_solver="full"', "angle_sklearn_full"),
        ("sklearn_randomized_s", 'sklearn PCA svd_solver="randomized"', "angle_sklearn_randomized"),
        ("pca_lowrank_s", "torch.pca_lowrank(q=k+10, niter=2)", "angle_pca_lowrank"),
    ):
        extra = f"   max principal angle to ours {e[angle]:.1e} rad" if angle else ""
        print(f"  {label:<40} {e[key]:8.4f} s  {e[key] / e['ours_s']:6.2f}x ours{extra}")
    print(f"  (Gram product alone {e['ours_gram_only_s']:.4f} s)")
    print(
        f"  ours vs sklearn full: {e['speedup_vs_sklearn_full']:.1f}x faster (target >= 10x: "
        f"{_met(e['speedup_vs_sklearn_full'] >= 10)})"
    )
    print(
        f"  ours / pca_lowrank: {e['ratio_to_pca_lowrank']:.2f} (target <= 1.5: "
        f"{_met(e['ratio_to_pca_lowrank'] <= 1.5)})"
    )
    print(
        f"  roofline: 2·N·P² = {flops / 1e9:.1f} GFLOP in {e['ours_s']:.3f} s = {e['achieved_gflops']:.1f} GFLOP/s, "
        f"{100 * e['gemm_fraction']:.0f}% of GEMM"
    )


def _section_scaling(results: dict[str, Any], quick: bool) -> None:
    # Objects at 64x64 (N = 4096): 1,000 objects are P = 41,000 views, past N, where the
    # exact fit folds the N×N scatter (at 128x128 that is 22 TFLOP, minutes, for any method).
    objects_size = 64
    s = results["scaling"] = bench_scaling(
        [32, 64] if quick else [32, 64, 128, 256],
        [5, 10, 20] if quick else [10, 30, 100, 300, 1000],
        5 if quick else 20,
        objects_size,
        _PANEL,
    )
    print(
        "\n== scaling: seconds and extra peak resident memory of one fit, each in a fresh subprocess "
        "(peak RSS sampled every ms, minus the RSS just before the fit; views generated on the fly "
        f"count). explicit = Eigenspace on the stacked views; exact = StreamingEigenspace (Gram by "
        f"panels of {_PANEL} views when N > P, else the N×N scatter); randomized = range finder"
    )
    print("-- image size (objects fixed, 41 views each)")
    print(_table(s["by_size"], _SCALING_COLS))
    print(f"-- number of objects ({objects_size}x{objects_size} views, 41 per object): P = 41 x objects")
    print(_table(s["by_objects"], _SCALING_COLS))


def _section_coil100(results: dict[str, Any], quick: bool) -> None:
    n = 10 if quick else 100
    c = results["coil100"] = bench_coil100(n, 1025, explicit=not quick)
    print(
        f"\n== COIL-100 sized build: {n} objects x 41 views x 3x128x128 synthetic (exact: panels of 1025 views;"
        " pipeline: flow + synthesis of every object into a disk cache, then StreamingEigenspace's default"
        " method from it)"
    )
    print(
        _table(c, [*_SCALING_COLS, ("workers", "workers", "d"), ("workers MiB", "workers_peak_mib", ".0f")])
    )
    for row in c:
        if row["kind"] != "pipeline":
            continue
        kind = row.get("worker_kind", "process")
        plural = "processes" if kind == "process" else "threads"
        where = f"{row['workers']} worker {plural}" if row["workers"] else "in one process, torch's threads"
        target = (
            f"target for 100 objects: 60 s, {_met(row['seconds'] <= 60)}"
            if n == 100
            else "the 60 s target is for 100 objects"
        )
        print(
            f"  pipeline, {where}: {row['seconds']:.1f} s in all ({row['synthesis_s']:.1f} s flow + "
            f"synthesis), peak {row['peak_mib']:.0f} MiB here + {row['workers_peak_mib']:.0f} MiB in "
            f"workers ({target})"
        )


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the benchmarks, prints them, optionally writes JSON and a PNG; returns 0."""
    args = _parser().parse_args(argv)
    with threads(args.threads):  # the commands' policy, restored on return
        return _main(args)


def _main(args: argparse.Namespace) -> int:
    parser = _parser()
    if args.worker is not None:
        print(json.dumps(run_case(json.loads(args.worker))))
        return 0
    try:
        check_outputs([("--json", args.json), ("--png", args.png)])  # before the timings, not after
        if args.root is not None and not os.path.isdir(args.root):
            # The stand-in is for the default folder only: a folder the user names must exist.
            raise ValueError(f"--root={args.root!r} is not an existing folder of COIL-20 images")
    except ValueError as exc:
        parser.exit(2, f"eigview bench: error: {exc}\n")
    root = args.root if args.root is not None else _DEFAULT_ROOT
    quick = args.quick
    reps = 2 if quick else 5
    results: dict[str, Any] = {"quick": quick, "torch": torch.__version__, "threads": torch.get_num_threads()}
    print(
        f"torch_eigview benchmarks (torch {torch.__version__}, {torch.get_num_threads()} threads, quick={quick})"
    )
    if "gemm" in args.sections or "eigen" in args.sections:
        _section_gemm(results, quick, reps)
    if "warp" in args.sections:
        _section_warp(results, quick, reps)
    if "eigen" in args.sections:
        _section_eigen(results, root, quick, reps)
    if "scaling" in args.sections:
        _section_scaling(results, quick)
    if "coil100" in args.sections:
        _section_coil100(results, quick)
    run_sections(args.sections, results, root, quick)
    try:
        if args.json:
            write_json(args.json, results)
            print(f"\nwrote {args.json}")
        if args.png:
            plot_results(results, args.png)
            print(f"wrote {args.png}")
    except OSError as exc:  # disk full or the like: the figures above are printed, say what failed
        parser.exit(2, f"eigview bench: error: {exc}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
