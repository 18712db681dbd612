"""Benchmark: the synthesis stage of ``eigview coil`` alone, one thread against worker threads.

Each COIL-20 object's seed pair at 0° and α is matched first (not timed); then its 41
views over −20°..20° are synthesized from that geometry (the maps, the warp and the size
normalization: what ``eigview coil`` times as ``synthesis``), once object after object
on one torch thread and once over ``--workers`` threads, one object each
(:func:`~torch_eigview.scale.parallel.map_ordered`, the commands' default). It prints the
wall seconds of each as JSON and checks that both give the same views. This prints
figures, it is not a timed test:

``python examples/bench_synthesis.py --root ../shared/data/coil-20-proc [--alpha 10] [--workers 2] [--frame 0.55]``

``--frame F`` shrinks each object to F of the frame on a zero background first (a
photograph with a margin round the object, its background set to 0, as a background
model or a segmentation leaves it): the maps are then built for the rows the object
touches (``NovelViewWarp.maps``' ``support``), and ``--whole-grid`` builds them for every
row instead, the same views, for comparison.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import time
import warnings
from collections.abc import Iterator

import torch
import torch.nn.functional as F

from torch_eigview.datasets import CoilFolder, find_coil_root
from torch_eigview.scale import available_cpus, threads
from torch_eigview.scale.parallel import map_ordered
from torch_eigview.synthesis import ElevationFallbackWarning, pair_geometry, synthesize_views
from torch_eigview.warp.novel_view import NovelViewWarp


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
    parser.add_argument(
        "--frame",
        type=float,
        default=1.0,
        help="shrink each object to this share of the frame on a zero background (default 1: as stored)",
    )
    parser.add_argument(
        "--whole-grid", action="store_true", help="build the maps for every row (no row band), for comparison"
    )
    args = parser.parse_args(argv)
    if not 0.1 <= args.frame <= 1.0:
        parser.error(f"--frame must lie in [0.1, 1], got {args.frame}")
    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    if args.objects < 1 or args.workers < 1:
        parser.error(f"--objects and --workers must be >= 1, got {args.objects} and {args.workers}")
    warnings.simplefilter("ignore", ElevationFallbackWarning)
    thetas = torch.arange(-20.0, 21.0)
    with threads(1):
        seeds = [
            _framed(folder.images(o, [0.0, args.alpha]), args.frame) for o in folder.objects[: args.objects]
        ]
        jobs = [(s, pair_geometry(s, args.alpha)) for s in seeds]

        def one(s: torch.Tensor, geometry: list) -> torch.Tensor:  # type: ignore[type-arg]
            return synthesize_views(s, args.alpha, thetas, geometry=geometry).views

        with _whole_grid():  # the first object's views without the row band (not timed)
            reference = one(*jobs[0])
        with _whole_grid() if args.whole_grid else contextlib.nullcontext():
            same = torch.equal(one(*jobs[0]), reference)  # and the warm-up
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
        "frame": args.frame,
        "whole_grid": args.whole_grid,
        "same_as_whole_grid": same,
    }
    print(json.dumps(result))
    return result


@contextlib.contextmanager
def _whole_grid() -> Iterator[None]:
    """Within it the warp builds its maps for every row, ignoring ``support`` (restored after)."""
    banded = NovelViewWarp.maps

    def whole_grid(self, correspondence, thetas, n_sources=2, *, support=None):  # type: ignore[no-untyped-def]
        return banded(self, correspondence, thetas, n_sources)

    NovelViewWarp.maps = whole_grid  # type: ignore[method-assign]
    try:
        yield
    finally:
        NovelViewWarp.maps = banded  # type: ignore[method-assign]


def _framed(seeds: torch.Tensor, share: float, background: float = 0.05) -> torch.Tensor:
    """(V, C, H, W) seeds shrunk to ``share`` of the frame, centred on a zero background
    (pixels at or below ``background`` set to 0, as a foreground mask would leave them)."""
    if share == 1.0:
        return seeds
    small = F.interpolate(seeds, scale_factor=share, mode="bilinear", align_corners=False)
    small = torch.where(small > background, small, 0.0)
    out = torch.zeros_like(seeds)
    (h, w), (sh, sw) = seeds.shape[-2:], small.shape[-2:]
    top, left = (h - sh) // 2, (w - sw) // 2
    out[..., top : top + sh, left : left + sw] = small
    return out


if __name__ == "__main__":
    main()
