"""The synthesis stage of ``eigview coil`` alone: one thread against worker threads.

Each COIL-20 object's seed pair at 0° and α is matched first (not timed); then its 41
views over −20°..20° are synthesized from that geometry (the maps, the warp and the size
normalization: what ``eigview coil`` times as ``synthesis``), once object after object
on one torch thread (the reference of the ratio) and once over ``--workers`` threads, one
object each (``map_ordered``, the commands' default); both must give the same views.

``--frame F`` shrinks each object to F of the frame on a zero background first (a
photograph with a margin round the object, its background set to 0, as a background
model or a segmentation leaves it): the maps are then built for the rows the object
touches (``NovelViewWarp.maps``' ``support``), and ``--whole-grid`` builds them for every
row instead, the same views, for comparison. Run from the repository root:

``python benchmarks/bench_synthesis.py [--root DIR] [--alpha 10] [--workers 2] [--frame 0.55] [--whole-grid] [--quick] [--out FILE]``
"""

from __future__ import annotations

import contextlib
import sys
import time
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_synthesis.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import torch
import torch.nn.functional as F

from benchmarks._coil import coil_root
from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from torch_eigview.datasets import CoilFolder
from torch_eigview.scale import available_cpus, threads
from torch_eigview.scale.parallel import map_ordered
from torch_eigview.synthesis import ElevationFallbackWarning, PairGeometry, pair_geometry, synthesize_views
from torch_eigview.warp import NovelViewWarp


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "3 objects over 2 worker threads")
    p.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    p.add_argument("--alpha", type=float, default=10.0, help="seed angle, degrees")
    p.add_argument("--objects", type=int, default=20, help="the first N objects")
    p.add_argument(
        "--workers", type=int, default=available_cpus(), help="worker threads (default: one per CPU)"
    )
    p.add_argument(
        "--frame",
        type=float,
        default=1.0,
        help="shrink each object to this share of the frame on a zero background (default 1: as stored)",
    )
    p.add_argument(
        "--whole-grid", action="store_true", help="build the maps for every row (no row band), for comparison"
    )
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    if not 0.1 <= args.frame <= 1.0:
        p.error(f"--frame must lie in [0.1, 1], got {args.frame}")
    folder = CoilFolder(coil_root(p, args.root))
    if args.objects < 1 or args.workers < 1:
        p.error(f"--objects and --workers must be >= 1, got {args.objects} and {args.workers}")
    if args.quick:
        args.objects, args.workers = 3, 2
    thetas = torch.arange(-20.0, 21.0)
    with threads(1), warnings.catch_warnings():
        warnings.simplefilter("ignore", ElevationFallbackWarning)
        seeds = [
            _framed(folder.images(o, [0.0, args.alpha]), args.frame) for o in folder.objects[: args.objects]
        ]
        jobs = [(s, pair_geometry(s, args.alpha)) for s in seeds]

        def one(s: torch.Tensor, geometry: list[PairGeometry]) -> torch.Tensor:
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
        "seconds": {"one thread": middle - start, "threads": end - middle},
        "same_views": all(torch.equal(a, b) for a, b in zip(alone, pooled, strict=True)),
        "frame": args.frame,
        "whole_grid": args.whole_grid,
        "same_as_whole_grid": same,
    }
    one_s, pooled_s = result["seconds"]["one thread"], result["seconds"]["threads"]
    t = table(
        f"Synthesis of {result['views']} views of {len(jobs)} COIL-20 objects (α = {args.alpha:g}, frame "
        f"{args.frame:g}, {'whole grid' if args.whole_grid else 'row band'}): seconds, ratio to one thread",
        ["run", "seconds", "× one thread", "same views"],
        [
            ["one thread", one_s, 1.0, True],
            [f"{args.workers} worker threads", pooled_s, pooled_s / one_s, result["same_views"]],
        ],
    )
    print(format_table(t))
    write_record(
        out,
        title="Synthesis stage: one thread against worker threads",
        command=command_line(__file__, argv),
        tables=[t],
        raw={"quick": args.quick, **result},
    )
    return result


@contextlib.contextmanager
def _whole_grid() -> Iterator[None]:
    """Within it the warp builds its maps for every row, ignoring ``support`` (restored after)."""
    banded = NovelViewWarp.maps

    def whole_grid(
        self: NovelViewWarp, correspondence: Any, thetas: Any, n_sources: int = 2, *, support: Any = None
    ) -> Any:
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
