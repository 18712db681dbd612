"""Every pose of the turntable as the first seed: COIL-20 recognition per center.

The paper's COIL experiment starts from the front view (center 0°). Here the seed views
lie at C and C + α for C = 0°, 90°, 180°, 270°, with the synthesized range −20°..20° and
the tests C − 45°..C + 45° every 5° around each (k = 15; ``eigview coil --alpha A
--center C``). Two tables:

- per center at ``--alpha`` (10°): ``nvs`` with the guided flow (the default) and with
  TV-L1 alone, ``dense`` (the 9 real views over −20°..20°) and ``sparse`` (the 2 seeds),
  and the ``nvs`` misses split into those inside the synthesized range and those beyond
  it (the misses themselves, object@angle, are in the record's raw figures);
- per α (``--alphas``) and correspondence (``--flows``: the guided flow, TV-L1 alone,
  the row matcher alone), ``nvs`` per center and the mean over centers, with ``sparse``
  from the same seeds.

Run: ``python examples/paper/every_center.py [--root DIR] [--alpha 10] [--alphas 5 10 15]``
"""

from __future__ import annotations

import argparse
import statistics
import time

from record import (
    add_objects_flag,
    add_record_flag,
    add_root_flag,
    check_record,
    coil_folder,
    command_line,
    table,
    write_record,
)

from torch_eigview import CoilFolder, SynthesisOptions
from torch_eigview.evaluation import CoilExperiment, CoilResult
from torch_eigview.scale import threads

FLOWS = ("guided", "tvl1", "rows")


def misses(folder: CoilFolder, exp: CoilExperiment, result: CoilResult) -> tuple[list[str], list[str]]:
    """The test views ``result``'s recognizer takes for another object, as ``object@angle``
    (degrees from the center), inside the synthesized range and beyond it."""
    start, stop = exp.synth_range()
    objects = list(exp.objects or folder.objects)
    inside: list[str] = []
    beyond: list[str] = []
    for a in range(round(exp.test[0]), round(exp.test[1]) + 1, 5):
        for obj in objects:
            pred = result.recognizer.predict(folder.images(obj, [exp.center + a]))
            if int(pred.labels[0]) != obj:
                (inside if start <= a <= stop else beyond).append(f"{obj}@{a:+d}")
    return inside, beyond


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_root_flag(parser)
    parser.add_argument("--centers", type=float, nargs="+", default=[0.0, 90.0, 180.0, 270.0])
    parser.add_argument("--alpha", type=float, default=10.0, help="the per-center table's α")
    parser.add_argument(
        "--alphas", type=float, nargs="*", default=[5.0, 10.0, 15.0], help="the flows table's α"
    )
    parser.add_argument("--flows", nargs="+", choices=FLOWS, default=list(FLOWS))
    parser.add_argument("--components", type=int, default=15)
    add_objects_flag(parser)
    add_record_flag(parser, "every_center")
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    folder = coil_folder(parser, args.root)
    cache: dict[tuple[str, str, float, float], CoilResult] = {}
    results: dict[str, dict[str, object]] = {}

    def run(method: str, flow: str, alpha: float, center: float) -> CoilResult:
        key = (method, flow if method == "nvs" else "-", alpha, center)
        if key not in cache:
            exp = CoilExperiment(
                alpha=alpha,
                center=center,
                method=method,
                components=args.components,
                objects=args.objects,
                synthesis=SynthesisOptions(flow=flow if method == "nvs" else "guided"),
            )
            t0 = time.perf_counter()
            cache[key] = exp.run(folder)
            results[f"{key[0]} {key[1]} alpha={alpha:g} center={center:g}"] = cache[key].to_json()
            print(
                f"alpha={alpha:g} center={center:g} {method} {key[1]:7s} {cache[key].accuracy:6.2f}% "
                f"({time.perf_counter() - t0:.1f} s)",
                flush=True,
            )
        return cache[key]

    flows = list(args.flows)
    per_center, missed = [], {}
    for c in args.centers:
        nvs = [run("nvs", flow, args.alpha, c) for flow in flows[:2]]
        exp = CoilExperiment(alpha=args.alpha, center=c, components=args.components, objects=args.objects)
        inside, beyond = misses(folder, exp, run("nvs", flows[0], args.alpha, c))
        missed[f"{c:g}"] = {"inside": inside, "beyond": beyond}
        per_center.append(
            [
                c,
                *(r.accuracy for r in nvs),
                run("dense", "-", args.alpha, c).accuracy,
                run("sparse", "-", args.alpha, c).accuracy,
                f"{len(inside)} / {len(beyond)}",
            ]
        )
    n_objects = len(args.objects or folder.objects)
    tables = [
        table(
            f"Seeds at C and C + {args.alpha:g}°, synthesized −20°..20° every 1°, k = {args.components}, "
            f"tests C − 45°..C + 45° every 5° ({n_objects} objects); accuracy (%).",
            [
                "center",
                *(f"nvs, {flow}" for flow in flows[:2]),
                "dense (real views every 5°)",
                "sparse (2 seeds)",
                f"nvs ({flows[0]}) misses inside / beyond the synthesized range",
            ],
            per_center,
        )
    ]
    if args.alphas:
        rows = []
        for alpha in args.alphas:
            for flow in [*flows, "sparse"]:
                accs = [
                    (
                        run("sparse", "-", alpha, c) if flow == "sparse" else run("nvs", flow, alpha, c)
                    ).accuracy
                    for c in args.centers
                ]
                rows.append([alpha, flow, *accs, statistics.fmean(accs)])
        tables.append(
            table(
                "nvs per center with each correspondence (guided: the row matcher's matches refined by "
                "TV-L1, the default; tvl1: TV-L1 alone; rows: the row matcher alone), and sparse from the "
                "same seeds; accuracy (%).",
                ["α", "flow", *(f"{c:g}°" for c in args.centers), "mean"],
                rows,
            )
        )
    write_record(
        args.record,
        title="COIL-20 recognition per center (every pose of the turntable)",
        command=command_line(__file__, argv),
        tables=tables,
        misses=missed,
        results=results,
    )
    return {"tables": tables, "misses": missed, "results": results}


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
