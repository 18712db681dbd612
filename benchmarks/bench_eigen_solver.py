"""The eigen step of a large gallery: the subspace solver against the Gram path.

The gallery is every COIL-20 view 5° apart and three copies shifted by 3 pixels (right,
down, both; a mirror image would make eigenvalues coincide): 4 × 20 × 72 = 5,760 views ×
16,384 values, unit rows, past ``SUBSPACE_MIN`` on both sides, so
``Eigenspace(k)``'s "auto" runs the subspace iteration. Both solvers fit it in turn,
``--rounds`` times, on torch's current threads: the seconds of each, the ratio of the
medians (the Gram path is the reference), the solver "auto" ran and the largest principal
angle between the two eigenspaces. Run from the repository root:

``python benchmarks/bench_eigen_solver.py [--root DIR] [--components 15] [--rounds 2] [--quick] [--out FILE]``
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_eigen_solver.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import torch

from benchmarks._coil import coil_root
from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from torch_eigview.datasets import CoilFolder
from torch_eigview.decomposition import Eigenspace
from torch_eigview.nn import unit_rows

SHIFTS = [(0, 0), (0, 3), (3, 0), (3, 3)]


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(
        __file__, __doc__, "3 objects (864 views: below SUBSPACE_MIN, both run the Gram path), 1 round"
    )
    p.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    p.add_argument("--components", type=int, default=15, help="k")
    p.add_argument("--rounds", type=int, default=2, help="fits of each solver, in turn")
    p.add_argument("--objects", type=int, default=20, help="the first N objects")
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    folder = CoilFolder(coil_root(p, args.root))
    if args.components < 1 or args.rounds < 1 or args.objects < 1:
        p.error(
            f"--components, --rounds and --objects must be >= 1, got {args.components}, {args.rounds}, {args.objects}"
        )
    if args.quick:
        args.objects, args.rounds = 3, 1
    views = torch.cat([folder.images(o, list(range(0, 360, 5))) for o in folder.objects[: args.objects]])
    x = unit_rows(torch.cat([views.roll(shift, dims=(-2, -1)) for shift in SHIFTS]))
    seconds: dict[str, list[float]] = {"auto": [], "gram": []}
    fits: dict[str, Eigenspace] = {}
    for _ in range(args.rounds):
        for solver in seconds:
            start = time.perf_counter()
            fits[solver] = Eigenspace(args.components, solver=solver).fit(x)
            seconds[solver].append(time.perf_counter() - start)
    # The largest principal angle from its sine, the projection's residual: the arccosine
    # of the cosines cannot resolve angles below about 3e-4 rad in float32.
    qa, qb = (torch.linalg.qr(fits[s].components_.double().T).Q for s in ("auto", "gram"))
    sine = torch.linalg.svdvals(qb - qa @ (qa.T @ qb)).max().clamp(max=1)
    medians = {solver: statistics.median(s) for solver, s in seconds.items()}
    result = {
        "views": list(x.shape),
        "k": args.components,
        "threads": torch.get_num_threads(),
        "auto_ran": fits["auto"].solver_,
        "seconds": seconds,
        "ratio_of_medians": medians["auto"] / medians["gram"],
        "max_principal_angle_rad": float(sine.asin()),
    }
    angle = result["max_principal_angle_rad"]
    t = table(
        f"Eigen step of {x.shape[0]} × {x.shape[1]} views, k = {args.components}, on "
        f"{result['threads']} thread(s): median seconds of {args.rounds} round(s), ratio to the Gram path",
        ["solver", "ran", "median s", "× gram", "angle to gram (rad)"],
        [
            ['"auto"', result["auto_ran"], medians["auto"], result["ratio_of_medians"], angle],
            ['"gram"', "gram", medians["gram"], 1.0, None],
        ],
    )
    print(format_table(t))
    write_record(
        out,
        title="Eigen step of a large gallery: the subspace solver against the Gram path",
        command=command_line(__file__, argv),
        tables=[t],
        raw={"quick": args.quick, **result},
    )
    return result


if __name__ == "__main__":
    main()
