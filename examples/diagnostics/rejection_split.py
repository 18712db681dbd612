"""Rejection at the rate asked for: known and unknown COIL-20 objects, the operating point and the ROC.

Objects 1–10 are known from two seed views (``center`` and ``center + α``, α = 10), fitted
as ``eigview fit`` fits them (``FewViewEigenspace``'s defaults: the gallery every degree
from 20° before the first seed to 20° past the second, 15 components) with
``reject_rate`` (0.05, ``eigview fit``'s default). Objects 11–20 are unknown. Every real
view over ``--test-poses`` around ``center`` (−45°..45° every 5°), the seed views left
out, is judged. Two calibrations of the same gallery, on views synthesized at
``reject_poses`` (default: every 2.5° from 45° before the first seed to 45° past the
second), are compared:

- ``default``: what ``FewViewEigenspace`` does, the poses the gallery holds left out;
- ``every pose``: every pose counted alike, a pose the gallery holds replaced by the
  gallery's mid-pose next to it (measured, not taken: see
  :mod:`torch_eigview.method.rejection`).

Per centre and calibration: the DIFS threshold, the calibration's own estimate of the
fraction of known views it rejects (``FewViewEigenspace.reject_rate_estimate_``), the
fractions of the known and unknown real views rejected, and the ROC: the most unknown views
rejected while at most 1, 2, 5 or 10 % of the known views are (the limit on the score
swept; the same for both calibrations with one score). With several ``--centers`` the
last rows are each calibration's median over the centres.

Run: ``python examples/diagnostics/rejection_split.py [--root DIR] [--centers 0 90]
[--test-poses -45 45 5]``
"""

from __future__ import annotations

import argparse
import math
import statistics
from typing import cast

import torch
from diagnostic_record import (
    add_record_flag,
    add_root_flag,
    check_record,
    coil_folder,
    command_line,
    objects_arg,
    table,
    text,
    write_record,
)

from torch_eigview import CoilFolder, FewViewEigenspace, synthesize_views
from torch_eigview.method import calibrate_rejection, estimate_reject_rate
from torch_eigview.scale import threads

#: The known-view fractions at which the ROC is read.
ROC_AT = (0.01, 0.02, 0.05, 0.10)

#: ``reject_poses``' default: every 2.5 degrees from 45 before the first seed to 45 past the last.
REJECT_MARGIN, REJECT_STEP = 45.0, 2.5


def grid(start: float, stop: float, step: float) -> list[float]:
    """``start, start + step, …, stop`` (inclusive)."""
    return [start + i * step for i in range(round((stop - start) / step) + 1)]


def roc_at(known: torch.Tensor, unknown: torch.Tensor, at: tuple[float, ...] = ROC_AT) -> list[float]:
    """The most unknown views (a fraction) rejected by a limit on the scores that rejects at
    most each fraction ``at`` of the known views (scores: (K,) and (U,), larger is stranger)."""
    limits = torch.cat([known, unknown]).unique()
    rows = [(float((known > c).double().mean()), float((unknown > c).double().mean())) for c in limits]
    rows.append((0.0, 0.0))
    return [max(u for k, u in rows if k <= a) for a in at]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_root_flag(parser)
    parser.add_argument("--known", type=objects_arg, default=list(range(1, 11)), help="known objects (1-10)")
    parser.add_argument("--unknown", type=objects_arg, default=list(range(11, 21)), help="unknown objects")
    parser.add_argument(
        "--centers",
        type=float,
        nargs="+",
        default=[0.0],
        help="the first seed's poses, degrees, one split each",
    )
    parser.add_argument("--alpha", type=float, default=10.0, help="degrees between the two seeds")
    parser.add_argument("--components", type=int, default=15)
    parser.add_argument("--reject-rate", type=float, default=0.05)
    parser.add_argument("--reject-score", choices=("difs", "dffs", "both"), default="difs")
    parser.add_argument(
        "--reject-poses",
        type=float,
        nargs=3,
        default=None,
        metavar=("START", "STOP", "STEP"),
        help="held-out poses from the first seed (default: the estimator's, 45 degrees past each seed)",
    )
    parser.add_argument(
        "--test-poses",
        type=float,
        nargs=3,
        default=[-45.0, 45.0, 5.0],
        metavar=("START", "STOP", "STEP"),
        help="the judged real views' poses from the first seed, the seeds left out",
    )
    add_record_flag(parser, "rejection_split")
    return parser


def split_rows(folder: CoilFolder, args: argparse.Namespace, center: float) -> tuple[list[list[object]], int]:
    """The rows of both calibrations for the split whose first seed is at ``center``, and
    the number of known views judged."""
    seed_poses = [center, center + args.alpha]
    test = [center + p for p in grid(*args.test_poses)]
    test = [p for p in test if all(abs(p - s) > 1e-6 for s in seed_poses)]
    seeds = torch.stack([folder.images(o, seed_poses) for o in args.known])
    known_views = torch.cat([folder.images(o, test) for o in args.known])
    unknown_views = torch.cat([folder.images(o, test) for o in args.unknown])
    poses = "around-seeds" if args.reject_poses is None else tuple(args.reject_poses)
    est = FewViewEigenspace(
        args.components, reject_rate=args.reject_rate, reject_score=args.reject_score, reject_poses=poses
    ).fit(seeds, seed_poses, labels=args.known)
    rec = est.recognizer_
    calibrations = {
        "default": (rec.reject_thresholds.clone(), est.reject_rate_estimate_, est.n_calibration_views_)
    }

    from_first = est.gallery_poses_[est.gallery_labels_ == args.known[0]] - center
    gallery = sorted(((from_first + 180) % 360 - 180).tolist())  # from the first seed, wrapped
    held_range = args.reject_poses or [-REJECT_MARGIN, args.alpha + REJECT_MARGIN, REJECT_STEP]
    thetas = []
    for t in grid(*held_range):  # a gallery pose becomes the mid-pose towards the next one
        i = min(range(len(gallery)), key=lambda j: abs(gallery[j] - t))
        on = abs(gallery[i] - t) <= 1e-6
        thetas.append(t + (gallery[i + 1 if i + 1 < len(gallery) else i - 1] - gallery[i]) / 2 if on else t)
    held = [synthesize_views(seeds[i], args.alpha, thetas).views for i in range(len(args.known))]
    held_views = torch.cat(held)
    groups = torch.arange(len(held)).repeat_interleave(len(thetas))
    every_estimate = estimate_reject_rate(rec, held_views, groups, args.reject_rate, args.reject_score)
    calibrate_rejection(rec, held_views, args.reject_rate, args.reject_score)
    calibrations["every pose"] = (rec.reject_thresholds.clone(), every_estimate, len(held_views))

    rows: list[list[object]] = []
    for name, (thresholds, estimate, n_views) in calibrations.items():
        rec.set_rejection(thresholds)
        known = rec.rejection_scores(known_views).double()
        unknown = rec.rejection_scores(unknown_views).double()
        t_dffs, t_difs = thresholds.tolist()
        rows.append(
            [
                f"{center:g}",
                name,
                n_views,
                t_difs if math.isfinite(t_difs) else math.nan,
                t_dffs if math.isfinite(t_dffs) else math.nan,
                100 * estimate if estimate is not None else math.nan,
                100 * float((known > 1).double().mean()),
                100 * float((unknown > 1).double().mean()),
                *(100 * u for u in roc_at(known, unknown)),
            ]
        )
    return rows, len(known_views)


def main(argv: list[str] | None = None) -> list[list[object]]:
    parser = _parser()
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    folder = coil_folder(parser, args.root)
    rows: list[list[object]] = []
    try:
        for center in args.centers:
            got, n_known = split_rows(folder, args, center)
            rows += got
    except ValueError as exc:  # a pose off the 5-degree grid, an object not in the folder
        parser.error(str(exc))
    if len(args.centers) > 1:
        for name in ("default", "every pose"):
            mine = [cast(list[float], r[2:]) for r in rows if r[1] == name]
            rows.append(["median", name, *(statistics.median(column) for column in zip(*mine, strict=True))])
    tab = table(
        f"COIL-20: objects {args.known[0]}–{args.known[-1]} known (seeds at center and center + "
        f"{args.alpha:g}), {args.unknown[0]}–{args.unknown[-1]} unknown, real views center "
        f"{args.test_poses[0]:+g}..{args.test_poses[1]:+g} every {args.test_poses[2]:g} degrees less the "
        f"seeds ({n_known} known, as many unknown per center); reject_rate={args.reject_rate:g}, "
        f"score {args.reject_score}. est: the calibration's own estimate (%), rej: real views "
        "rejected (%), ROC: unknown rejected (%) at most 1/2/5/10 % of the known rejected.",
        [
            "center",
            "calibration",
            "views",
            "t_difs",
            "t_dffs",
            "est",
            "known rej",
            "unknown rej",
            *(f"ROC {a:.0%}" for a in ROC_AT),
        ],
        rows,
    )
    print(text(tab))
    write_record(
        args.record,
        title="Diagnosis: rejection at the rate asked for",
        command=command_line(__file__, argv),
        tables=[tab],
    )
    return rows


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
