"""Time and peak memory of one eigenspace fit as the views grow: explicit, streaming exact and randomized.

Each fit runs in a fresh process (``_fit_case.py``: peak resident set sampled every
millisecond, minus the resident set just before the fit; views generated on the fly
count), on random smooth views of 41 per object, k = 15:

- *explicit*: :class:`~torch_eigview.Eigenspace` on the stacked views (the reference of
  the ratios);
- *exact*: :class:`~torch_eigview.StreamingEigenspace`, the Gram matrix by panels of 205
  views where N > P, else the N×N scatter from chunks;
- *randomized*: its randomized range finder.

Two series: growing image sides at a fixed number of objects, and growing numbers of
objects at 64 × 64 (N = 4096: 1,000 objects are P = 41,000 views, past N, where the exact
fit folds the N×N scatter). Run from the repository root:

``python benchmarks/bench_scaling.py [--quick] [--png FILE] [--out FILE]``
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_scaling.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks._fit_case import measure
from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from torch_eigview.files import check_output_path

KINDS = ("explicit", "exact", "randomized")
PANEL = 205  # views per panel of the exact Gram path (5 objects): memory is a panel plus P²
OBJECTS_SIZE = 64


def bench_scaling(sizes: Sequence[int], objects: Sequence[int], size_objects: int) -> dict[str, Any]:
    """Every kind at every size (``size_objects`` objects) and every number of objects (64 × 64)."""
    spec = {"channels": 1, "k": 15, "max_views": PANEL}
    by_size = [
        measure({**spec, "kind": kind, "objects": size_objects, "size": s}) for s in sizes for kind in KINDS
    ]
    by_objects = [
        measure({**spec, "kind": kind, "objects": n, "size": OBJECTS_SIZE}) for n in objects for kind in KINDS
    ]
    return {"by_size": by_size, "by_objects": by_objects}


def scaling_table(rows: Sequence[dict[str, Any]], caption: str) -> dict[str, Any]:
    """One series; each row's seconds and peak over those of the explicit fit of its size."""
    explicit = {(r["objects"], r["size"]): r for r in rows if r["kind"] == "explicit"}

    def over(r: dict[str, Any], key: str) -> float | None:
        ref = explicit.get((r["objects"], r["size"]))
        return r[key] / ref[key] if ref is not None and ref[key] > 0 else None

    return table(
        caption,
        [
            "kind",
            "objects",
            "size",
            "seconds",
            "s / explicit",
            "peak MiB",
            "peak / explicit",
            "passes",
            "P·N·4 MiB",
            "min(P,N)²·8 MiB",
            "held views MiB",
        ],
        [
            [
                r["kind"],
                r["objects"],
                r["size"],
                r["seconds"],
                over(r, "seconds"),
                r["peak_mib"],
                over(r, "peak_mib"),
                r["passes"],
                r["data_matrix_mib"],
                r["gram_mib"],
                r["held_mib"],
            ]
            for r in rows
        ],
    )


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "sides 32 and 64 (5 objects), 5/10/20 objects")
    p.add_argument("--png", default=None, metavar="FILE", help="the figure of both series (matplotlib)")
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    if args.png:
        try:
            check_output_path(args.png, "--png")
        except ValueError as exc:
            p.error(str(exc))
    if args.quick:
        raw = bench_scaling([32, 64], [5, 10, 20], 5)
    else:
        raw = bench_scaling([32, 64, 128, 256], [10, 30, 100, 300, 1000], 20)
    n_size = raw["by_size"][0]["objects"]
    tables = [
        scaling_table(
            raw["by_size"], f"Image side, {n_size} objects of 41 views: seconds and extra peak memory"
        ),
        scaling_table(
            raw["by_objects"],
            f"Number of objects, 41 views of {OBJECTS_SIZE}×{OBJECTS_SIZE} each: seconds and extra peak memory",
        ),
    ]
    print(*(format_table(t) for t in tables), sep="\n\n")
    notes = (
        "Each fit in a fresh process; peak is the resident growth during the fit, generated views "
        f"included. Held views: what a streaming fit keeps at once (a panel of {PANEL} views and a "
        "chunk for the Gram path, N/2 views for the scatter path, one object's block for the "
        "randomized one)."
    )
    write_record(
        out,
        title="Eigenspace scaling: time and peak memory of explicit, streaming exact and randomized fits",
        command=command_line(__file__, argv),
        tables=tables,
        notes=notes,
        raw={"quick": args.quick, "panel": PANEL, **raw},
    )
    if args.png:
        from benchmarks._plot import plot_scaling

        plot_scaling(raw, Path(args.png))
        print(f"wrote {args.png}")
    return raw


if __name__ == "__main__":
    main()
