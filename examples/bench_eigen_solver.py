"""Benchmark: the eigen step of a large gallery, the subspace solver against the Gram path.

The gallery is every COIL-20 view 5° apart and three copies shifted by 3 pixels (right,
down, both; a mirror image would make eigenvalues coincide): 4 × 20 × 72 = 5,760 views ×
16,384 values, unit rows, past
``SUBSPACE_MIN`` on both sides, so ``Eigenspace(k)``'s "auto" runs the subspace
iteration (:mod:`torch_eigview.decomposition.subspace`). Both solvers fit it in turn,
``--rounds`` times, on torch's current threads; it prints the wall seconds of each, the
solver that ran, and the largest principal angle between the two eigenspaces as JSON.
This prints figures, it is not a timed test:

``python examples/bench_eigen_solver.py --root ../shared/data/coil-20-proc [--components 15] [--rounds 2]``
"""

from __future__ import annotations

import argparse
import json
import time

import torch

from torch_eigview.datasets import CoilFolder, find_coil_root
from torch_eigview.decomposition import Eigenspace
from torch_eigview.nn.functional import unit_rows


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    parser.add_argument("--components", type=int, default=15, help="k")
    parser.add_argument("--rounds", type=int, default=2, help="fits of each solver, in turn")
    parser.add_argument("--objects", type=int, default=20, help="the first N objects")
    args = parser.parse_args(argv)
    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    if args.components < 1 or args.rounds < 1 or args.objects < 1:
        parser.error(
            f"--components, --rounds and --objects must be >= 1, got {args.components}, {args.rounds}, {args.objects}"
        )
    views = torch.cat([folder.images(o, list(range(0, 360, 5))) for o in folder.objects[: args.objects]])
    shifts = [(0, 0), (0, 3), (3, 0), (3, 3)]
    x = unit_rows(torch.cat([views.roll(shift, dims=(-2, -1)) for shift in shifts]))
    seconds: dict[str, list[float]] = {"auto": [], "gram": []}
    fits: dict[str, Eigenspace] = {}
    for _ in range(args.rounds):
        for solver in seconds:
            start = time.perf_counter()
            fits[solver] = Eigenspace(args.components, solver=solver).fit(x)
            seconds[solver].append(round(time.perf_counter() - start, 3))
    # The largest principal angle from its sine, the projection's residual: the arccosine
    # of the cosines cannot resolve angles below about 3e-4 rad in float32.
    qa, qb = (torch.linalg.qr(fits[s].components_.double().T).Q for s in ("auto", "gram"))
    sine = torch.linalg.svdvals(qb - qa @ (qa.T @ qb)).max().clamp(max=1)
    result = {
        "views": list(x.shape),
        "k": args.components,
        "threads": torch.get_num_threads(),
        "auto_ran": fits["auto"].solver_,
        "seconds": seconds,
        "ratio_of_medians": round(
            sorted(seconds["auto"])[len(seconds["auto"]) // 2]
            / sorted(seconds["gram"])[len(seconds["gram"]) // 2],
            3,
        ),
        "max_principal_angle_rad": float(sine.asin()),
    }
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
