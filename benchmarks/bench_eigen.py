"""The eigen step on the COIL-20 gallery matrix: ours against scikit-learn's PCA and torch.pca_lowrank.

The (820, 16384) matrix of the ``nvs`` gallery of COIL-20 (two seed views 5° apart per
object, 41 views over −20°..20°, unit rows; random smooth views of the same size where
the images are absent, or at a smaller size with ``--quick``), k = 15. Each method is
timed (best of a few repeats) and compared with :class:`~torch_eigview.Eigenspace`:

- its seconds over ours, and the largest principal angle between its subspace and ours;
- ``sklearn.decomposition.PCA`` with ``svd_solver="full"`` and ``"randomized"``;
- ``torch.pca_lowrank(q=k+10, niter=2)``.

Beside it, the roofline: a float32 GEMM's rate on this machine and the share of it the
Gram product (2·N·P² flops) reaches. Run from the repository root:

``python benchmarks/bench_eigen.py [--root DIR] [--quick] [--threads N] [--out FILE]``
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_eigen.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import numpy as np
import torch

from benchmarks._coil import default_coil_root
from benchmarks._record import (
    add_threads,
    check_out,
    command_line,
    format_table,
    parser,
    record_path,
    table,
    write_record,
)
from benchmarks._timing import best_of
from benchmarks._views import smooth_views
from torch_eigview import CoilFolder, Eigenspace, synthesize_views
from torch_eigview.decomposition.linalg import gram
from torch_eigview.nn import unit_rows
from torch_eigview.scale import threads

K = 15


def gallery_matrix(root: Path | None, quick: bool) -> tuple[torch.Tensor, str]:
    """The (820, 16384) nvs gallery of COIL-20 at ``root`` with unit rows, or a stand-in."""
    if root is not None and not quick:
        folder = CoilFolder(root)
        thetas = list(range(-20, 21))
        views = [synthesize_views(folder.images(o, [0.0, 5.0]), 5.0, thetas).views for o in folder.objects]
        x, what = torch.cat(views).flatten(1), f"COIL-20 nvs views ({root.name})"
    else:
        n_obj, size = (5, 64) if quick else (20, 128)
        x = torch.cat([smooth_views(o, 41, 1, size) for o in range(n_obj)]).flatten(1)
        what = "random smooth views" + (" (--quick)" if quick else " (COIL-20 absent)")
    return unit_rows(x).contiguous(), what


def _angle(a: np.ndarray | torch.Tensor, b: torch.Tensor) -> float:
    """The largest principal angle (radians) between the row spaces of ``a`` and ``b``."""
    q = torch.linalg.qr(torch.as_tensor(np.asarray(a), dtype=torch.float64).T).Q
    return float(torch.arccos(torch.linalg.svdvals(q.T @ b.double().T).clamp(max=1.0).min()))


def bench_eigen(x: torch.Tensor, k: int, repeats: int) -> dict[str, Any]:
    """Seconds of ours (Gram), scikit-learn's PCA (full, randomized) and torch.pca_lowrank,
    and each one's largest principal angle to ours."""
    from sklearn.decomposition import PCA

    xn = x.numpy()
    ours = Eigenspace(k).fit(x).components_
    xc = x - x.mean(0)
    out: dict[str, Any] = {"P": x.shape[0], "N": x.shape[1], "k": k}
    out["ours_s"] = best_of(lambda: Eigenspace(k).fit(x), repeats)
    out["gram_s"] = best_of(lambda: gram(xc), repeats)
    out["sklearn_full_s"] = best_of(lambda: PCA(k, svd_solver="full").fit(xn), max(1, repeats // 3))
    out["sklearn_randomized_s"] = best_of(
        lambda: PCA(k, svd_solver="randomized", random_state=0).fit(xn), repeats
    )
    out["pca_lowrank_s"] = best_of(lambda: torch.pca_lowrank(x, q=k + 10, niter=2), repeats)
    out["angle_sklearn_full"] = _angle(PCA(k, svd_solver="full").fit(xn).components_, ours)
    out["angle_sklearn_randomized"] = _angle(
        PCA(k, svd_solver="randomized", random_state=0).fit(xn).components_, ours
    )
    out["angle_pca_lowrank"] = _angle(torch.pca_lowrank(x, q=k + 10, niter=2)[2][:, :k].T, ours)
    return out


def bench_gemm(n: int, repeats: int) -> dict[str, Any]:
    """A float32 ``torch.mm`` of two n × n matrices: seconds and GFLOP/s."""
    a, b = torch.randn(n, n), torch.randn(n, n)
    t = best_of(lambda: torch.mm(a, b), repeats)
    return {"n": n, "seconds": t, "gflops": 2 * n**3 / t / 1e9}


def _met(ok: bool) -> str:
    return "met" if ok else "NOT met"


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "5 objects of 64x64 random smooth views, 2 repeats")
    p.add_argument(
        "--root",
        default=None,
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else "
        "../shared/data/coil-20-proc; random smooth views where that is absent)",
    )
    add_threads(p)
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    if args.root is not None and not Path(args.root).is_dir():
        # The stand-in is for the default folder only: a folder the user names must exist.
        p.error(f"--root={args.root!r} is not an existing folder of COIL-20 images")
    root = Path(args.root) if args.root is not None else default_coil_root()
    repeats = 2 if args.quick else 5
    with threads(args.threads) as n_threads:
        x, what = gallery_matrix(root if root.is_dir() else None, args.quick)
        gemm = bench_gemm(1024 if args.quick else 2048, repeats)
        e = bench_eigen(x, K, repeats)
    flops = 2.0 * e["N"] * e["P"] ** 2  # the Gram matrix as a GEMM counts it
    e["achieved_gflops"] = flops / e["ours_s"] / 1e9
    e["gemm_fraction"] = e["achieved_gflops"] / gemm["gflops"]
    methods = table(
        f"Eigen step of the {e['P']} × {e['N']} matrix, k = {K} ({what}, {n_threads} thread(s)): "
        "seconds, ratio to ours, largest principal angle to ours",
        ["method", "seconds", "× ours", "angle to ours (rad)"],
        [
            [label, e[key], e[key] / e["ours_s"], e[angle] if angle else None]
            for key, label, angle in (
                ("ours_s", "ours (Eigenspace, Gram)", None),
                ("sklearn_full_s", 'sklearn PCA svd_solver="full"', "angle_sklearn_full"),
                ("sklearn_randomized_s", 'sklearn PCA svd_solver="randomized"', "angle_sklearn_randomized"),
                ("pca_lowrank_s", f"torch.pca_lowrank(q={K + 10}, niter=2)", "angle_pca_lowrank"),
            )
        ],
    )
    roofline = table(
        "Roofline: a float32 GEMM's rate and the share of it the eigen step reaches (2·N·P² flops)",
        ["GEMM n", "GEMM s", "GEMM GFLOP/s", "Gram product s", "eigen step GFLOP/s", "share of GEMM"],
        [[gemm["n"], gemm["seconds"], gemm["gflops"], e["gram_s"], e["achieved_gflops"], e["gemm_fraction"]]],
    )
    speedup, lowrank = e["sklearn_full_s"] / e["ours_s"], e["ours_s"] / e["pca_lowrank_s"]
    notes = (
        f"Ours is {speedup:.1f}× faster than scikit-learn's full SVD (target ≥ 10×: {_met(speedup >= 10)}) "
        f"and takes {lowrank:.2f}× the time of torch.pca_lowrank (target ≤ 1.5: {_met(lowrank <= 1.5)})."
    )
    print(format_table(methods), format_table(roofline), notes, sep="\n\n")
    raw = {"data": what, "threads": n_threads, "quick": args.quick, "eigen": e, "gemm": gemm}
    write_record(
        out,
        title="Eigen step: ours against scikit-learn's PCA and torch.pca_lowrank",
        command=command_line(__file__, argv),
        tables=[methods, roofline],
        notes=notes,
        raw=raw,
    )
    return raw


if __name__ == "__main__":
    main()
