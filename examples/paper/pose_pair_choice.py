"""Which seed pair should measure a view's pose? The geometric pose's pair rule, diagnosed.

``eigview coil --seeds 8 --pose three-view`` measures each correctly recognized view by Eq. 2
against the seed pair whose sector holds its appearance pose (the pose interpolated on the
eigenspace's manifold), and against the neighbouring pair where Eq. 2 puts it past a seed
(:func:`~torch_eigview.synthesis.seed_pair_poses`). Here every such view is measured
against three pairs: its appearance sector's and both neighbours' (two flows each, the
points chained through the view and Eq. 2 fitted to their columns as the library does,
``pose_fit.py``), and the pose error of several ways to choose among them is printed:

- ``library``: the library's rule, from the same measurements (it reproduces the command's
  pose errors);
- ``most points``: the pair whose two flows leave the most trusted chained points, among
  the appearance pair and its neighbour on the side of the nearer seed, or among all three;
- ``most trusted``: the pair whose flows trust the largest shares of the view (product of
  both flows' trusted shares), among the same candidates;
- ``true sector``: the pair whose sector holds the true pose (an oracle: it reads the
  truth; what any rule that chooses among these three pairs can reach at best);
- ``appearance``: the appearance pose itself, no geometry.

This prints figures, it is not a test. It reads the test views' true poses; a diagnosis, not
a method. It takes about a minute per object on two CPU cores:

``python examples/paper/pose_pair_choice.py [--root DIR] [--seeds 8] [--objects 1-20]``
"""

from __future__ import annotations

import argparse
import math
import statistics
import warnings
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import torch
from pose_fit import MIN_POINTS, chain_columns, column_weight, fit_view_angle, wrap_degrees
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

from torch_eigview import estimate_correspondence
from torch_eigview.evaluation import CoilExperiment
from torch_eigview.scale import available_cpus, threads
from torch_eigview.synthesis import ElevationFallbackWarning, SynthesisOptions
from torch_eigview.warp import foreground_mask

Measure = dict[str, float]  # theta (degrees from the pair's first seed), points, trusted


def measure(views: torch.Tensor, two: torch.Tensor, alpha: float, opts: SynthesisOptions) -> list[Measure]:
    """:func:`~torch_eigview.synthesis.view_angles` of (N, C, H, W) ``views`` between ``two``
    seeds, with the chained points it fits and the shares of the view each flow trusts."""
    fg = foreground_mask(two[:1], opts.background)[0]
    kwargs = opts.flow_kwargs(alpha / 2)
    to_view = estimate_correspondence(
        two[:1].expand_as(views), views, method=opts.flow, threshold=opts.threshold, **kwargs
    )
    to_seed2 = estimate_correspondence(
        views, two[1:].expand_as(views), method=opts.flow, threshold=opts.threshold, **kwargs
    )
    x1, x2, x3, use = chain_columns(to_view, to_seed2, fg)
    weight = column_weight(two[0])
    theta = fit_view_angle(x1, x2, x3, use, alpha, weight=weight)
    points = (use & (weight > 0)).sum(dim=1)
    trusted = to_view.valid_12.double().mean((1, 2)) * to_seed2.valid_12.double().mean((1, 2))
    return [
        {"theta": float(t), "points": float(p), "trusted": float(s)}
        for t, p, s in zip(theta.tolist(), points.tolist(), trusted.tolist(), strict=True)
    ]


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_root_flag(parser)
    parser.add_argument("--seeds", type=int, default=8, help="M, seeds round the circle (>= 3)")
    add_objects_flag(parser)
    parser.add_argument("--every", type=int, default=1, help="measure every N-th test pose (a quick look)")
    add_record_flag(parser, "pose_pair_choice")
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    folder = coil_folder(parser, args.root)
    if args.seeds < 3:
        parser.error(f"--seeds must be >= 3 (seeds 180 degrees apart leave Eq. 2 singular), got {args.seeds}")
    if args.every < 1:
        parser.error(f"--every must be >= 1, got {args.every}")
    warnings.simplefilter("ignore", ElevationFallbackWarning)
    objects = list(folder.objects if args.objects is None else args.objects)
    exp = CoilExperiment(seeds=args.seeds, objects=objects, interpolate_pose=True)
    recognizer = exp.run(folder).recognizer
    layout = exp.circle(folder, objects)
    seeds, m, step = layout.seeds, len(layout.seeds), layout.alpha
    opts = exp.synthesis
    tests = layout.tests[:: args.every]

    def one(obj: int) -> list[tuple[float, float, dict[int, Measure]]]:
        """(truth, appearance pose, {offset: measure}) of each recognized view of ``obj``."""
        views = folder.images(obj, tests)
        pred = recognizer.predict(views, interpolate_pose=True)
        ok = (pred.labels == obj).nonzero()[:, 0]
        rough = [(p - seeds[0]) % 360.0 for p in pred.poses[ok].double().tolist()]
        sector = [int(r // step) % m for r in rough]
        images = folder.images(obj, seeds)
        found: dict[tuple[int, int], Measure] = {}
        for off in (-1, 0, 1):
            pairs = [(s + off) % m for s in sector]
            for k in sorted(set(pairs)):
                sel = [i for i, p in enumerate(pairs) if p == k]
                for i, meas in zip(
                    sel, measure(views[ok[sel]], images[[k, (k + 1) % m]], step, opts), strict=True
                ):
                    found[(i, off)] = {**meas, "base": k * step}
        truth = [tests[i] - seeds[0] for i in ok.tolist()]
        return [(truth[i], rough[i], {off: found[(i, off)] for off in (-1, 0, 1)}) for i in range(len(ok))]

    # One object per thread, one torch thread each (the flows release the GIL), in order.
    with threads(1), ThreadPoolExecutor(available_cpus()) as pool:
        records = [r for part in pool.map(one, objects) for r in part]

    def pose(meas: Measure) -> float:
        return meas["base"] + meas["theta"]

    def library(rough: float, cand: dict[int, Measure]) -> float:
        first = cand[0]
        if math.isnan(first["theta"]):
            return rough
        out = pose(first)
        for side in (-1, 1):
            if (side < 0 and first["theta"] < 0) or (side > 0 and first["theta"] > step):
                other = cand[side]
                if 0 <= other["theta"] <= step:  # False for NaN
                    out = pose(other)
        return out

    Rule = Callable[[float, float, dict[int, Measure]], float]  # (truth, appearance pose, pairs)

    def best(key: str, near_only: bool) -> Rule:
        def rule(truth: float, rough: float, cand: dict[int, Measure]) -> float:
            near = -1 if rough % step < step / 2 else 1
            offs = (0, near) if near_only else (-1, 0, 1)
            ok = [cand[o] for o in offs if not math.isnan(cand[o]["theta"])]
            return pose(max(ok, key=lambda c: c[key])) if ok else rough

        return rule

    def oracle(truth: float, rough: float, cand: dict[int, Measure]) -> float:
        inside = [c for c in cand.values() if 0 <= (truth - c["base"]) % 360.0 < step]
        if not inside or math.isnan(inside[0]["theta"]):
            return library(rough, cand)
        return pose(inside[0])

    rules: dict[str, Rule] = {
        "library": lambda t, r, c: library(r, c),
        "most points (appearance pair, nearer neighbour)": best("points", True),
        "most points (all three)": best("points", False),
        "most trusted (appearance pair, nearer neighbour)": best("trusted", True),
        "most trusted (all three)": best("trusted", False),
        "true sector (oracle)": oracle,
        "appearance": lambda t, r, c: r,
    }
    if not records:
        print("no test view was recognized: nothing to measure")
        return {"rules": {}, "records": [], "library_poses": [], "seeds": seeds}
    few = sum(c[0]["points"] < MIN_POINTS for _, _, c in records)
    print(
        f"M = {m}, {len(records)} recognized views of {len(objects)} objects; {few} with fewer than "
        f"{MIN_POINTS} trusted points in the appearance pair (they keep the appearance pose)"
    )
    print(f"{'rule':50s} {'mean':>7s} {'median':>7s} {'> 20 deg':>9s}")
    summary: dict[str, dict[str, float]] = {}
    for name, rule in rules.items():
        errors = (
            wrap_degrees(torch.tensor([rule(t, r, c) - t for t, r, c in records], dtype=torch.float64))
            .abs()
            .tolist()
        )
        row = summary[name] = {
            "mean": statistics.fmean(errors),
            "median": statistics.median(errors),
            "over_20": sum(e > 20 for e in errors),
        }
        print(f"{name:50s} {row['mean']:7.2f} {row['median']:7.2f} {row['over_20']:9d}")
    library_poses = [(seeds[0] + library(r, c)) % 360.0 for _, r, c in records]
    write_record(
        args.record,
        title="Which seed pair measures a view's pose (the geometric pose's pair rule)",
        command=command_line(__file__, argv),
        tables=[
            table(
                f"M = {m}, {len(records)} recognized views of {len(objects)} objects, each measured against "
                "three seed pairs (its appearance sector's and both neighbours'); the pose error (degrees) of "
                f"each way to choose among them. {few} views have fewer than {MIN_POINTS} trusted points in "
                "the appearance pair and keep the appearance pose.",
                ["rule", "mean", "median", "views > 20°"],
                [[name, row["mean"], row["median"], row["over_20"]] for name, row in summary.items()],
            )
        ],
        rules=summary,
    )
    return {"rules": summary, "records": records, "library_poses": library_poses, "seeds": seeds}


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
