"""Seconds per stage of the COIL experiment: correspondence, maps, warp, eigen step, recognition.

``CoilExperiment(alpha=10, objects=...)`` (what ``eigview coil --alpha 10 --objects ...``
runs) on COIL-20, its own times per stage and each stage's share of the total; the
synthesis is split on each object's first seed pair into ``NovelViewWarp.maps`` and
``apply_maps``, measured again apart. Run from the repository root:

``python benchmarks/bench_stages.py [--root DIR] [--quick] [--threads N] [--out FILE]``
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_stages.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import torch

from benchmarks._coil import coil_root
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
from torch_eigview import CoilFolder, NovelViewWarp
from torch_eigview.evaluation import CoilExperiment
from torch_eigview.scale import threads
from torch_eigview.synthesis import pair_geometry

THETAS = list(range(-20, 21))
STAGES = ("correspondence", "synthesis", "eigen", "recognition", "total")


def bench_stages(root: Path, objects: Sequence[int], alpha: float = 10.0) -> dict[str, Any]:
    """Per-stage seconds of the COIL experiment on ``objects``, and the maps and the warp of
    each object's first seed pair measured apart."""
    folder = CoilFolder(root)
    result = CoilExperiment(alpha=alpha, objects=list(objects)).run(folder)
    maps_s = warp_s = 0.0
    for obj in objects:
        seeds = folder.images(obj, [0.0, alpha])
        geo = pair_geometry(seeds, alpha)[0]
        warp = NovelViewWarp(alpha, elevation=geo.elevation)
        t0 = time.perf_counter()
        maps = warp.maps(geo.correspondence, THETAS)
        t1 = time.perf_counter()
        warp.apply_maps(maps, seeds[:, None])
        maps_s, warp_s = maps_s + t1 - t0, warp_s + time.perf_counter() - t1
    return {
        "objects": list(objects),
        "alpha": alpha,
        "threads": torch.get_num_threads(),
        "accuracy": result.accuracy,
        "seconds": dict(result.seconds),
        "maps_s": maps_s,
        "warp_s": warp_s,
    }


def stages_table(s: dict[str, Any]) -> dict[str, Any]:
    sec = s["seconds"]
    total = sec["total"]
    rows = [[key, sec.get(key), sec[key] / total if key in sec else None] for key in STAGES]
    rows += [
        ["  maps (first seed pairs)", s["maps_s"], s["maps_s"] / total],
        ["  warp (first seed pairs)", s["warp_s"], s["warp_s"] / total],
    ]
    return table(
        f"CoilExperiment(alpha={s['alpha']:g}) on {len(s['objects'])} COIL-20 objects, "
        f"{s['threads']} thread(s): seconds per stage and share of the total",
        ["stage", "seconds", "share of total"],
        rows,
    )


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "objects 1 and 2")
    p.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    add_threads(p)
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    root = coil_root(p, args.root)
    with threads(args.threads):
        s = bench_stages(root, [1, 2] if args.quick else [1, 2, 3, 4])
    t = stages_table(s)
    print(format_table(t))
    write_record(
        out,
        title="Stages of the COIL experiment",
        command=command_line(__file__, argv),
        tables=[t],
        raw={"quick": args.quick, **s},
    )
    return s


if __name__ == "__main__":
    main()
