"""Linear against kernel eigenspaces of the synthesized COIL-20 views (issue #6).

For α = 5, 10, 15 (seed views at 0° and α, 41 views synthesized over −20°..20°, 15
components, 1-NN over the 380 test views at −45°..45°), the same gallery goes into:

- ``linear``: the paper's eigenspace (``Eigenspace``);
- ``rbf``: ``KernelEigenspace(kernel="rbf", gamma="median")``, γ = 1/median squared
  distance between the unit-norm gallery views (sklearn's default 1/N would be ~1e-4 here:
  unit-norm views are at squared distances ≤ 2, so the kernel would be nearly linear);
- ``poly``: (γ x·y + 1)³ with γ = 1 (x·y ∈ [0, 1] for unit-norm non-negative views).

The cosine kernel is left out: on unit-norm views it is the linear kernel. After the table,
the Nyström approximation error ‖K − K̃‖_F/‖K‖_F of the rbf kernel on the α = 5 gallery.

The figures also go to a result record, ``examples/results/kernel_pca.json`` by default
(``docs/make_pages.py`` turns it into a section of ``docs/results.md``).

Run: ``python examples/kernel_pca.py [--root DIR] [--out kernel_pca.png]``
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from torch_eigview import CoilFolder, KernelEigenspace, KernelProjection, environment_info
from torch_eigview.datasets import find_coil_root
from torch_eigview.evaluation import CoilExperiment
from torch_eigview.files import check_output_path, write_json

RECORD = Path(__file__).resolve().parent / "results" / "kernel_pca.json"

METHODS: dict[str, dict[str, object]] = {
    "linear": {},
    "rbf": {"kernel": "rbf", "gamma": "median"},
    "poly": {"kernel": "poly", "gamma": 1.0},
}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    parser.add_argument("--alphas", type=float, nargs="+", default=[5, 10, 15])
    parser.add_argument("--out", default="kernel_pca.png", help="the PNG to write")
    parser.add_argument(
        "--record",
        default=str(RECORD),
        help="the JSON result record to write (default examples/results/kernel_pca.json; '' for none)",
    )
    args = parser.parse_args(argv)
    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    if args.record:
        if args.record == str(RECORD):
            RECORD.parent.mkdir(exist_ok=True)
        try:  # an unwritable record: say so before the runs, not after them
            check_output_path(args.record, "--record")
        except ValueError as exc:
            parser.error(str(exc))
    rows = []
    gallery = None
    for alpha in args.alphas:
        for name, kw in METHODS.items():
            t0 = time.perf_counter()
            result = CoilExperiment(alpha=alpha, **kw).run(folder)  # type: ignore[arg-type]
            wall = time.perf_counter() - t0
            proj = result.recognizer.projection
            gamma = proj.gamma if isinstance(proj, KernelProjection) else float("nan")
            if name == "rbf" and gallery is None and isinstance(proj, KernelProjection):
                gallery = (proj.vectors.clone(), proj.gamma)  # the unit-norm gallery views
            rows.append(
                dict(
                    alpha=alpha,
                    method=name,
                    gamma=gamma,
                    accuracy=result.accuracy,
                    pose=result.pose_mae_deg,
                    eigen=result.seconds["eigen"],
                    recognition=result.seconds["recognition"],
                    total=wall,
                )
            )
            print(f"alpha={alpha:g} {name:6s} {result.accuracy:6.2f}%  ({wall:.1f} s)", flush=True)

    print()
    print("COIL-20, 2 seed views, synth -20..20 step 1 (41 views/object), test -45..45, k = 15")
    header = f"{'alpha':>5} {'method':>7} {'gamma':>7} {'acc (%)':>8} {'pose MAE':>9} {'eigen s':>8} {'recog s':>8} {'total s':>8}"
    print(header)
    for r in rows:
        gamma = "-" if r["gamma"] != r["gamma"] else f"{r['gamma']:.3g}"
        print(
            f"{r['alpha']:5g} {r['method']:>7} {gamma:>7} {r['accuracy']:8.2f} {r['pose']:9.2f} "
            f"{r['eigen']:8.2f} {r['recognition']:8.2f} {r['total']:8.1f}"
        )

    nystrom = []
    if gallery is not None:
        views, gamma = gallery
        n = views.shape[0]
        print(f"\nNyström rbf kernel (gamma={gamma:.3g}) on the alpha={args.alphas[0]:g} gallery, P={n}:")
        for m in (n // 20, n // 10, n // 4, n // 2):
            est = KernelEigenspace(15, kernel="rbf", gamma=gamma, nystrom=m).fit(views)
            nystrom.append([m, est.nystrom_error(views)])
            print(f"  m={m:4d}: ||K - K~||_F / ||K||_F = {nystrom[-1][1]:.4f}")
    if args.record:
        write_record(args.record, argv, rows, nystrom)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
    for name in METHODS:
        sel = [r for r in rows if r["method"] == name]
        alphas = [r["alpha"] for r in sel]
        axes[0].plot(alphas, [r["accuracy"] for r in sel], marker="o", label=name)
        axes[1].plot(alphas, [r["pose"] for r in sel], marker="o", label=name)
    axes[0].set(xlabel="alpha (degrees)", ylabel="accuracy (%)", title="recognition, COIL-20")
    axes[1].set(xlabel="alpha (degrees)", ylabel="pose MAE (degrees)", title="pose error (correct matches)")
    for ax in axes:
        ax.set_xticks(args.alphas)
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"\nwrote {args.out}")


def write_record(
    path: str,
    argv: list[str] | None,
    rows: list[dict[str, object]],
    nystrom: list[list[float]],
) -> None:
    """The result record in ``docs/make_pages.py``'s format: the tables and the raw figures."""
    runs = [{**r, "gamma": None if r["gamma"] != r["gamma"] else r["gamma"]} for r in rows]  # NaN: linear
    script = Path(__file__).resolve()
    root = script.parents[1]
    shown = script.relative_to(root).as_posix() if script.is_relative_to(root) else str(script)
    tables = [
        {
            "caption": "COIL-20, two seed views at 0° and α, 41 views per object synthesized over −20°..20°, "
            "k = 15, 1-NN over the 380 test views at −45°..45°; accuracy (%) and the mean pose error "
            "(degrees) of the recognized views.",
            "columns": ["α", "eigenspace", "γ", "accuracy (%)", "pose error (°)"],
            "rows": [[r["alpha"], r["method"], r["gamma"], r["accuracy"], r["pose"]] for r in runs],
        }
    ]
    if nystrom:
        tables.append(
            {
                "caption": "Nyström approximation of the rbf kernel on the first α's gallery: "
                "‖K − K̃‖_F / ‖K‖_F with m landmarks.",
                "columns": ["m", "relative error"],
                "rows": nystrom,
            }
        )
    record = {
        "title": "Linear against kernel eigenspaces on COIL-20",
        "page": "results",
        "command": shlex.join(["python", shown, *(sys.argv[1:] if argv is None else argv)]),
        "environment": environment_info(),
        "tables": tables,
        "runs": runs,
    }
    write_json(path, record, default=str)
    print(f"record written to {path}")


if __name__ == "__main__":
    main()
