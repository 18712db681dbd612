"""Warping 41 views of two seed views: kornia's sampling against the sparse G·C product and scikit-image.

For growing image sides, the same views three ways, each the best of a few repeats and
in a ratio to the first (the module :class:`~torch_eigview.NovelViewWarp` runs):

- *kornia*: ``NovelViewWarp.apply_maps``, kornia's ``remap`` of both seed views, blended;
- *sparse G·C*: :class:`~torch_eigview.SparseViewOperator`'s product of Eqs. 3–6 (and,
  apart, the seconds to build G and C);
- *skimage*: a loop over the views and seeds with ``skimage.transform.warp``.

The sparse product and the scikit-image loop run up to 128 pixels a side only (they take
minutes beyond); larger rows are kornia's alone. Run from the repository root:

``python benchmarks/bench_warp.py [--quick] [--threads N] [--out FILE]``
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_warp.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import numpy as np
import torch

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
from torch_eigview import NovelViewWarp, SparseViewOperator
from torch_eigview.geometry import correspondence_from_disparity
from torch_eigview.scale import threads

SLOW_MAX = 128  # the largest side of the sparse G·C and scikit-image comparisons


def warp_row(size: int, n_views: int, repeats: int) -> dict[str, Any]:
    """The three warps of ``n_views`` views at ``size`` × ``size``: seconds and largest differences."""
    from skimage.transform import warp as sk_warp

    thetas = torch.linspace(-20, 20, n_views, dtype=torch.float64)
    seeds = smooth_views(0, 2, 1, size)  # (2, 1, H, W)
    disparity = -2.0 * torch.sin(torch.linspace(0, math.pi, size))[None, :].expand(size, size).contiguous()
    warp = NovelViewWarp(5.0, elevation=0.0)
    maps = warp.maps(correspondence_from_disparity(disparity), thetas)
    t_kornia = best_of(lambda: NovelViewWarp.apply_maps(maps, seeds[:, None]), repeats)
    if size > SLOW_MAX:
        return {"size": size, "views": n_views, "kornia_s": t_kornia, "skipped": True}
    t_build = best_of(lambda: SparseViewOperator.from_maps(seeds, maps), max(1, repeats // 2))
    op = SparseViewOperator.from_maps(seeds, maps)
    t_sparse = best_of(op.views, repeats)

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

    t_skimage = best_of(skimage_loop, max(1, repeats // 2))
    ref = NovelViewWarp.apply_maps(maps, seeds[:, None])[0, :, 0].double()
    return {
        "size": size,
        "views": n_views,
        "kornia_s": t_kornia,
        "sparse_views_s": t_sparse,
        "sparse_build_s": t_build,
        "skimage_loop_s": t_skimage,
        "max_diff_sparse": float((op.views()[:, 0].double() - ref).abs().max()),
        "max_diff_skimage": float((torch.from_numpy(skimage_loop()) - ref).abs().max()),
    }


def warp_table(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    def ratio(r: dict[str, Any], key: str) -> float | None:
        return r[key] / r["kornia_s"] if key in r else None

    return table(
        f"Warp of {rows[0]['views']} views from 2 seed views: seconds, ratios to kornia's sampling and "
        f"largest differences to its views (sparse G·C and the scikit-image loop up to {SLOW_MAX} pixels a side)",
        [
            "size",
            "kornia s",
            "sparse G·C s",
            "build G, C s",
            "skimage loop s",
            "sparse / kornia",
            "skimage / kornia",
            "sparse: largest difference",
            "skimage: largest difference",
        ],
        [
            [
                r["size"],
                r["kornia_s"],
                r.get("sparse_views_s"),
                r.get("sparse_build_s"),
                r.get("skimage_loop_s"),
                ratio(r, "sparse_views_s"),
                ratio(r, "skimage_loop_s"),
                r.get("max_diff_sparse"),
                r.get("max_diff_skimage"),
            ]
            for r in rows
        ],
    )


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "sides 32 and 64, 2 repeats")
    add_threads(p)
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    sizes, repeats = ([32, 64], 2) if args.quick else ([32, 64, 128, 256], 5)
    with threads(args.threads) as n_threads:
        rows = [warp_row(size, 41, repeats) for size in sizes]
    t = warp_table(rows)
    print(format_table(t))
    write_record(
        out,
        title="Warp: kornia sampling against the sparse G·C product and scikit-image",
        command=command_line(__file__, argv),
        tables=[t],
        raw={"threads": n_threads, "quick": args.quick, "rows": rows},
    )
    return {"threads": n_threads, "rows": rows}


if __name__ == "__main__":
    main()
