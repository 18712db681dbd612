"""One seed pair's correspondence: the guided flow, TV-L1 (torch, scikit-image) and the row matcher.

For each α, the COIL-20 objects' views at 0° and α are matched with
:func:`~torch_eigview.synthesis.pair_geometry` (both directions, the validity masks and
the elevation estimate: what ``eigview coil`` times as ``correspondence``), with
``flow="guided"`` (the default), ``"tvl1"`` (torch), ``"tvl1-skimage"`` (scikit-image's
TV-L1, the reference of the ratios) and ``"rows"``; the mean seconds per pair, on one
thread. Run from the repository root:

``python benchmarks/bench_correspondence.py [--root DIR] [--alpha 10 45] [--objects 20] [--quick] [--out FILE]``
"""

from __future__ import annotations

import sys
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_correspondence.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks._coil import coil_root
from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from torch_eigview.datasets import CoilFolder
from torch_eigview.scale import threads
from torch_eigview.synthesis import ElevationFallbackWarning, SynthesisOptions, pair_geometry

FLOWS = ("guided", "tvl1", "tvl1-skimage", "rows")
REFERENCE = "tvl1-skimage"


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "the first object at α = 20")
    p.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    p.add_argument("--alpha", type=float, nargs="+", default=[10.0, 45.0], help="seed angles, degrees")
    p.add_argument("--objects", type=int, default=20, help="the first N objects")
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    folder = CoilFolder(coil_root(p, args.root))
    if args.objects < 1:
        p.error(f"--objects must be >= 1, got {args.objects}")
    if args.quick:
        args.objects, args.alpha = 1, [20.0]
    objects = folder.objects[: args.objects]
    seconds: dict[str, dict[str, float]] = {}
    with threads(1), warnings.catch_warnings():
        warnings.simplefilter("ignore", ElevationFallbackWarning)
        for alpha in args.alpha:
            seeds = [folder.images(o, [0.0, alpha]) for o in objects]
            per_flow = seconds[f"{alpha:g}"] = {}
            for flow in FLOWS:
                options = SynthesisOptions(flow=flow)
                pair_geometry(seeds[0], alpha, options)  # warm-up
                start = time.perf_counter()
                for pair in seeds:
                    pair_geometry(pair, alpha, options)
                per_flow[flow] = (time.perf_counter() - start) / len(seeds)
    t = table(
        f"Correspondence of one seed pair (both directions, validity, elevation), mean of {len(objects)} "
        f"COIL-20 objects on one thread: seconds per pair, ratio to scikit-image's TV-L1",
        ["α", "flow", "seconds per pair", f"× {REFERENCE}"],
        [
            [float(alpha), flow, s, s / per_flow[REFERENCE]]
            for alpha, per_flow in seconds.items()
            for flow, s in per_flow.items()
        ],
    )
    print(format_table(t))
    result = {"objects": len(objects), "seconds_per_pair": seconds}
    write_record(
        out,
        title="Correspondence of a seed pair: guided flow, TV-L1 and the row matcher",
        command=command_line(__file__, argv),
        tables=[t],
        raw={"quick": args.quick, **result},
    )
    return result


if __name__ == "__main__":
    main()
