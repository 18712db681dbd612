"""Benchmark: one seed pair's correspondences: the guided flow, TV-L1 (torch, scikit-image), the row matcher.

For each α, the COIL-20 objects' views at 0° and α are matched with
:func:`~torch_eigview.synthesis.pair_geometry` (both directions, the validity masks and
the elevation estimate: what ``eigview coil`` times as ``correspondence``), with
``flow="guided"`` (the default), ``"tvl1"`` (torch), ``"tvl1-skimage"`` and ``"rows"``; the mean seconds per pair are printed as
JSON. This prints figures, it is not a timed test. Run it with one thread, and compare
two checkouts by running it in each in turn:

``python examples/bench_correspondence.py --root ../shared/data/coil-20-proc [--alpha 10 45]``
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import torch

from torch_eigview.datasets import CoilFolder, find_coil_root
from torch_eigview.synthesis import ElevationFallbackWarning, SynthesisOptions, pair_geometry


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    parser.add_argument("--alpha", type=float, nargs="+", default=[10.0, 45.0], help="seed angles, degrees")
    parser.add_argument("--objects", type=int, default=20, help="the first N objects")
    args = parser.parse_args(argv)
    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    if args.objects < 1:
        parser.error(f"--objects must be >= 1, got {args.objects}")
    torch.set_num_threads(1)
    warnings.simplefilter("ignore", ElevationFallbackWarning)
    seconds = {}
    for alpha in args.alpha:
        seeds = [folder.images(o, [0.0, alpha]) for o in folder.objects[: args.objects]]
        for flow in ("guided", "tvl1", "tvl1-skimage", "rows"):
            options = SynthesisOptions(flow=flow)
            pair_geometry(seeds[0], alpha, options)  # warm-up
            start = time.perf_counter()
            for pair in seeds:
                pair_geometry(pair, alpha, options)
            seconds[f"{flow} alpha={alpha:g}"] = round((time.perf_counter() - start) / len(seeds), 4)
    result = {"seconds_per_pair": seconds, "objects": min(args.objects, len(folder.objects))}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
