"""The full circle on COIL-20: M seed views all round the turntable, every other pose tested.

For each M: M seed views 360°/M apart from 0° (``eigview coil --seeds M``), every sector
between consecutive seeds synthesized (the one from the last seed back to the first
included), one eigenspace, 1-NN over every pose that is not a seed (72 − M per object).
Two settings, each with the correspondences of ``--flows`` (the guided flow, the default,
TV-L1 alone, the row matcher alone):

- k = 20, synthesized every ``--step`` (5°) degrees, the pose interpolated on the
  appearance manifold between the nearest gallery view and its neighbours
  (``eigview coil --seeds M --components 20 --synth 0 0 5 --pose interpolate``), beside
  the baselines: ``sparse``, the M seed views alone, and ``dense``, real views about
  every 180°/M (about 2M per object, tested on the other poses);
- ``eigview coil``'s defaults (``--seeds M``: k = 15, synthesized every 1°, the nearest
  gallery view's pose).

The pose error is the mean and median absolute error of the recognized ``nvs`` views.

Run: ``python examples/paper/full_circle.py [--root DIR] [--seeds 4 6 8 12] [--step 5]``
"""

from __future__ import annotations

import argparse
import dataclasses
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


def run(name: str, exp: CoilExperiment, folder: CoilFolder) -> CoilResult:
    t0 = time.perf_counter()
    result = exp.run(folder)
    print(f"{name:34s} {result.accuracy:6.2f}%  ({time.perf_counter() - t0:.1f} s)", flush=True)
    return result


def pose(result: CoilResult) -> str:
    """``mean / median`` pose error of the recognized views, degrees."""
    return f"{result.pose_mae_deg:.2f}° / {result.pose_median_deg:.2f}°"


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_root_flag(parser)
    parser.add_argument("--seeds", type=int, nargs="+", default=[4, 6, 8, 12], help="values of M")
    parser.add_argument("--step", type=float, default=5.0, help="the first table's synthesized step, degrees")
    parser.add_argument("--components", type=int, default=20, help="the first table's k")
    parser.add_argument("--flows", nargs="+", choices=FLOWS, default=list(FLOWS))
    parser.add_argument(
        "--no-defaults", action="store_true", help="leave out the table with eigview coil's defaults"
    )
    add_objects_flag(parser)
    add_record_flag(parser, "full_circle")
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    folder = coil_folder(parser, args.root)
    objects = list(args.objects or folder.objects)
    results: dict[str, dict[str, object]] = {}
    first, second = [], []
    for m in args.seeds:
        base = CoilExperiment(
            seeds=m,
            components=args.components,
            objects=objects,
            synth=(0.0, 0.0, args.step),
            interpolate_pose=True,
        )
        nvs = {}
        for flow in args.flows:
            exp = dataclasses.replace(base, synthesis=SynthesisOptions(flow=flow))
            nvs[flow] = run(f"M={m} k={args.components} step={args.step:g} {flow}", exp, folder)
            results[f"M={m} interpolated {flow}"] = nvs[flow].to_json()
        sparse = run(f"M={m} sparse", dataclasses.replace(base, method="sparse"), folder)
        dense = run(f"M={m} dense", dataclasses.replace(base, method="dense"), folder)
        results[f"M={m} sparse"], results[f"M={m} dense"] = sparse.to_json(), dense.to_json()
        first.append(
            [
                m,
                *(nvs[flow].accuracy for flow in args.flows),
                sparse.accuracy,
                dense.accuracy,
                dense.n_train_views // len(objects),
                pose(nvs[args.flows[0]]),
            ]
        )
        if not args.no_defaults:
            defaults = {}
            for flow in args.flows:
                exp = CoilExperiment(seeds=m, objects=objects, synthesis=SynthesisOptions(flow=flow))
                defaults[flow] = run(f"M={m} defaults {flow}", exp, folder)
                results[f"M={m} defaults {flow}"] = defaults[flow].to_json()
            second.append(
                [m, *(defaults[flow].accuracy for flow in args.flows), pose(defaults[args.flows[0]])]
            )
    tables = [
        table(
            f"k = {args.components}, synthesized every {args.step:g}°, pose interpolated on the manifold "
            f"({len(objects)} objects, 72 − M test poses each); accuracy (%), pose error of the recognized "
            f"nvs ({args.flows[0]}) views.",
            [
                "M",
                *(f"nvs, {flow}" for flow in args.flows),
                "sparse (M real)",
                "dense (≈2M real)",
                "dense views per object",
                "pose error mean / median",
            ],
            first,
        )
    ]
    if second:
        tables.append(
            table(
                "eigview coil's defaults (k = 15, synthesized every 1°, the nearest gallery view's pose); "
                f"accuracy (%), pose error of the recognized nvs ({args.flows[0]}) views.",
                ["M", *(f"nvs, {flow}" for flow in args.flows), "pose error mean / median"],
                second,
            )
        )
    write_record(
        args.record,
        title="COIL-20 full circle (every pose of the turntable)",
        command=command_line(__file__, argv),
        tables=tables,
        results=results,
    )
    return {"tables": tables, "results": results}


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
