"""Benchmark: the synthesis stage of ``eigview coil`` alone, one thread against worker threads.

Each COIL-20 object's seed pair at 0° and α is matched first (not timed); then its 41
views over −20°..20° are synthesized from that geometry (the maps, the warp and the size
normalization: what ``eigview coil`` times as ``synthesis``), once object after object
on one torch thread and once over ``--workers`` threads, one object each
(:func:`~torch_eigview.scale.parallel.map_ordered`, the commands' default). It prints the
wall seconds of each as JSON and checks that both give the same views. This prints
figures, it is not a timed test:

``python examples/bench_synthesis.py --root ../shared/data/coil-20-proc [--alpha 10] [--workers 2]``
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import torch

from torch_eigview.datasets import CoilFolder, find_coil_root
from torch_eigview.scale import available_cpus, threads
from torch_eigview.scale.parallel import map_ordered
from torch_eigview.synthesis import ElevationFallbackWarning, pair_geometry, synthesize_views


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    parser.add_argument("--alpha", type=float, default=10.0, help="seed angle, degrees")
    parser.add_argument("--objects", type=int, default=20, help="the first N objects")
    parser.add_argument(
        "--workers", type=int, default=available_cpus(), help="worker threads (default: one per CPU)"
    )
    args = parser.parse_args(argv)
    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    if args.objects < 1 or args.workers < 1:
        parser.error(f"--objects and --workers must be >= 1, got {args.objects} and {args.workers}")
    warnings.simplefilter("ignore", ElevationFallbackWarning)
    thetas = torch.arange(-20.0, 21.0)
    with threads(1):
        seeds = [folder.images(o, [0.0, args.alpha]) for o in folder.objects[: args.objects]]
        jobs = [(s, pair_geometry(s, args.alpha)) for s in seeds]

        def one(s: torch.Tensor, geometry: list) -> torch.Tensor:  # type: ignore[type-arg]
            return synthesize_views(s, args.alpha, thetas, geometry=geometry).views

        one(*jobs[0])  # warm-up
        start = time.perf_counter()
        alone = [one(*job) for job in jobs]
        middle = time.perf_counter()
        pooled = list(map_ordered(one, jobs, args.workers, kind="thread"))
        end = time.perf_counter()
    result = {
        "objects": len(jobs),
        "views": sum(v.shape[0] for v in alone),
        "workers": args.workers,
        "seconds": {"one thread": round(middle - start, 3), "threads": round(end - middle, 3)},
        "same_views": all(torch.equal(a, b) for a, b in zip(alone, pooled, strict=True)),
    }
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
