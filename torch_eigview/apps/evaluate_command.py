"""``eigview evaluate``: a model file against the views of a manifest.

Every view of an object the model knows is recognized after the model's own
preprocessing (:class:`~torch_eigview.io.preprocessing.Preprocessing`) and scored as
``eigview coil`` scores its test views (:func:`~torch_eigview.evaluation.scoring.score`):
accuracy, per-object accuracy, and the pose error (wrapped to (-180, 180]) of the correctly
recognized views, mean and median. A bad row (a missing or corrupt file, a mask of
another size or all background, a background colour that leaves no object, a non-numeric
angle, a duplicate view) is reported with its manifest line
and left out, and the others go on; the exit status is then 1. Views of objects the model
does not know are counted apart (``unknown_objects``): they are what rejection is scored
on, whose figures go in ``rejection`` (None while the recognizer has none).
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from torch_eigview.apps.cli_args import HelpFormatter, add_quiet, add_threads
from torch_eigview.apps.device_option import add_device_argument, resolve_device
from torch_eigview.apps.prediction import escape
from torch_eigview.apps.view_options import (
    add_manifest_arguments,
    check_not_views,
    load_manifest,
    manifest_inputs,
)
from torch_eigview.files import check_outputs, write_json

if TYPE_CHECKING:
    import torch

    from torch_eigview.datasets.manifest import ViewEntry
    from torch_eigview.io.model import Model
    from torch_eigview.io.preprocessing import Preprocessing
    from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = ["Evaluation", "add_evaluate_command", "evaluate", "format_evaluation", "run_evaluate"]


def add_evaluate_command(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``eigview evaluate`` and its options to the command's subparsers."""
    ev = sub.add_parser(
        "evaluate",
        help="score a model on the views of a manifest",
        description="Every view of the manifest prepared as the model records and recognized; prints the "
        "accuracy per object and in all, the pose error, and with --reject the rejection's rates.",
        formatter_class=HelpFormatter,
    )
    ev.add_argument(
        "--model", required=True, metavar="FILE", help="model file of eigview fit (or coil --save)"
    )
    add_manifest_arguments(ev)
    ev.add_argument(
        "--exclude-seeds", action="store_true", help="leave out the views at the model's seed azimuths"
    )
    ev.add_argument(
        "--pose",
        choices=("nearest", "interpolate"),
        default="nearest",
        help="the reported pose: the nearest gallery view's, or interpolated between its neighbours",
    )
    ev.add_argument(
        "--reject",
        action="store_true",
        help="answer 'unknown' where the model's calibrated rejection says so (eigview fit --reject-rate): "
        "report the known views rejected, the unknown objects' views rejected and the accuracy on the "
        "accepted known views",
    )
    ev.add_argument("--json", metavar="FILE", help="write the results as JSON")
    add_device_argument(ev, "the projection and the search run")
    add_quiet(ev)
    add_threads(ev)


@dataclass
class Evaluation:
    """The outcome of ``eigview evaluate``; :meth:`to_json` is its JSON record.

    Attributes:
        accuracy: correctly recognized views of known objects, % (NaN when none was read).
        per_object: the same per object name.
        pose_mean_deg, pose_median_deg: absolute pose error of the correctly recognized
            views, degrees (NaN when none is).
        n_test: the views scored.
        skipped: ``{"row": manifest line or file, "error": message}`` of each row left out.
        unknown_objects: views per object name that the model does not know.
        rejection: with ``--reject``: ``known_rejected`` and ``unknown_rejected`` (fractions
            of the known objects' and of the unknown objects' views answered "unknown", the
            latter None without such views), ``accuracy_accepted`` (% correct among the
            known views accepted), the counts and the thresholds; else None.
    """

    accuracy: float
    per_object: dict[str, float]
    pose_mean_deg: float
    pose_median_deg: float
    n_test: int
    skipped: list[dict[str, str]] = field(default_factory=list)
    unknown_objects: dict[str, int] = field(default_factory=dict)
    rejection: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        def finite(value: float) -> float | None:
            return value if math.isfinite(value) else None

        return {
            "accuracy": finite(self.accuracy),
            "per_object": self.per_object,
            "pose_error_deg": {"mean": finite(self.pose_mean_deg), "median": finite(self.pose_median_deg)},
            "n_test": self.n_test,
            "skipped": self.skipped,
            "unknown_objects": self.unknown_objects,
            "rejection": self.rejection,
        }


def _skip(skipped: list[dict[str, str]], message: str) -> None:
    """Records a bad row; the message starts with its manifest line (or file)."""
    row, _, error = message.partition(": ")
    skipped.append({"row": row, "error": error or message})


def _tests(
    groups: dict[str, list[ViewEntry]],
    table: dict[str, int],
    prep: Preprocessing,
    dtype: torch.dtype,
    skipped: list[dict[str, str]],
    device: torch.device,
) -> Iterator[tuple[str, int, torch.Tensor, torch.Tensor]]:
    """Per known object its readable views (B, C, H, W) and true poses (B,) on ``device``
    (the recognizer's), read lazily."""
    import torch

    from torch_eigview.datasets.background import background_rule
    from torch_eigview.datasets.image_views import read_view
    from torch_eigview.geometry.angles import wrap_degrees

    background = background_rule(prep.background, prep.colour, prep.tolerance)
    for obj, entries in groups.items():
        images, poses = [], []
        for e in entries:
            try:
                image, _ = read_view(
                    e.path,
                    e.mask,
                    size=prep.size,
                    channels=prep.channels,
                    dtype=dtype,
                    source=e.source,
                    background=background,
                )
                images.append(image)
                poses.append(e.azimuth)
            except ValueError as exc:
                _skip(skipped, str(exc))
        if images:
            truth = wrap_degrees(torch.tensor(poses, dtype=torch.float64)).to(dtype)
            yield obj, table[obj], torch.stack(images).to(device), truth.to(device)


class _Rejections:
    """Counts what rejection answers on the views passing through :meth:`watch`."""

    def __init__(self, recognizer: NearestNeighborRecognizer) -> None:
        if not recognizer.rejects:
            raise ValueError(
                "--reject needs a model with calibrated rejection (eigview fit without --no-reject); "
                "this one has none"
            )
        self.recognizer = recognizer
        self.known = self.known_rejected = self.accepted_correct = 0
        self.unknown = self.unknown_rejected = 0

    def watch(
        self, tests: Iterator[tuple[str, int, torch.Tensor, torch.Tensor]], known: bool
    ) -> Iterator[tuple[str, int, torch.Tensor, torch.Tensor]]:
        import torch

        for item in tests:
            with torch.no_grad():
                out = self.recognizer.predict(item[2], reject=True)
            assert out.known is not None
            rejected = int((~out.known).sum())
            if known:
                self.known += len(out.known)
                self.known_rejected += rejected
                self.accepted_correct += int((out.known & (out.labels == item[1])).sum())
            else:
                self.unknown += len(out.known)
                self.unknown_rejected += rejected
            yield item

    def figures(self) -> dict[str, Any]:
        accepted = self.known - self.known_rejected
        t_dffs, t_difs = (float(t) for t in self.recognizer.reject_thresholds)
        return {
            "known_rejected": self.known_rejected / self.known if self.known else None,
            "unknown_rejected": self.unknown_rejected / self.unknown if self.unknown else None,
            "accuracy_accepted": 100.0 * self.accepted_correct / accepted if accepted else None,
            "n_known": self.known,
            "n_unknown": self.unknown,
            "thresholds": {
                "dffs": t_dffs if math.isfinite(t_dffs) else None,
                "difs": t_difs if math.isfinite(t_difs) else None,
            },
        }


def evaluate(
    model: Model,
    entries: list[ViewEntry],
    *,
    skipped: list[dict[str, str]] | None = None,
    interpolate_pose: bool = False,
    reject: bool = False,
) -> Evaluation:
    """Recognizes and scores ``entries`` (a manifest's views) with a model and its preprocessing.

    Args:
        model: the loaded model (:func:`~torch_eigview.io.load_model`); its recognizer's
            label names are the object names, its preprocessing prepares the views.
        entries: the views, grouped by object in the order of their first view.
        skipped: rows already left out (bad manifest lines); unreadable views are added.
        interpolate_pose: score the pose interpolated on the appearance manifold.
        reject: also score the model's rejection on the known objects' views and on the
            views of objects it does not know (:attr:`Evaluation.rejection`).

    Raises:
        ValueError: no view of an object the model knows could be read; ``reject`` with a
            model that has no calibrated rejection.
    """
    from torch_eigview.evaluation.scoring import score

    recognizer, prep = model.recognizer, model.preprocessing
    skipped = [] if skipped is None else skipped
    table = model.label_table()
    groups: dict[str, list[ViewEntry]] = {}
    unknown: dict[str, int] = {}
    for e in entries:
        if e.object in table:
            groups.setdefault(e.object, []).append(e)
        else:
            unknown[e.object] = unknown.get(e.object, 0) + 1
    rejections = _Rejections(recognizer) if reject else None
    where = recognizer.codes.device  # the views go where the recognizer is (--device)
    # One object in memory at a time.
    tests = _tests(groups, table, prep, recognizer.codes.dtype, skipped, where)
    if rejections is not None:
        tests = rejections.watch(tests, known=True)
    first = next(tests, None)
    if first is None:
        known = ", ".join(list(table)[:10])
        raise ValueError(
            f"no view of an object the model knows ({known}) could be read; {len(skipped)} rows skipped"
        )
    result = score(recognizer, itertools.chain([first], tests), wrap=True, interpolate_pose=interpolate_pose)
    if rejections is not None:
        others: dict[str, list[ViewEntry]] = {}
        for e in entries:
            if e.object not in table:
                others.setdefault(e.object, []).append(e)
        for _ in rejections.watch(
            _tests(others, dict.fromkeys(others, -1), prep, recognizer.codes.dtype, skipped, where), False
        ):
            pass
    return Evaluation(
        result.accuracy,
        dict(result.per_object),
        result.pose_mae_deg,
        result.pose_median_deg,
        result.n_test,
        skipped,
        unknown,
        None if rejections is None else rejections.figures(),
    )


def format_evaluation(ev: Evaluation, title: str) -> str:
    """The per-object accuracy table, the total and the pose errors."""
    lines = [title, f"{'object':>12} {'accuracy (%)':>13}"]
    lines += [f"{escape(obj)[:12]:>12} {acc:13.2f}" for obj, acc in ev.per_object.items()]
    lines.append(f"{'Total':>12} {ev.accuracy:13.2f}")
    lines.append(
        f"test images {ev.n_test}, pose error of correct matches: mean {ev.pose_mean_deg:.2f} deg, "
        f"median {ev.pose_median_deg:.2f} deg"
    )
    if ev.unknown_objects:
        lines.append(
            f"views of objects the model does not know: {sum(ev.unknown_objects.values())} (not scored)"
        )
    if ev.rejection is not None:
        r = ev.rejection

        def pct(value: float | None) -> str:
            return "-" if value is None else f"{100 * value:.1f}%"

        acc = "-" if r["accuracy_accepted"] is None else f"{r['accuracy_accepted']:.2f}%"
        lines.append(
            f"rejection: known views rejected {pct(r['known_rejected'])} of {r['n_known']}, unknown objects' "
            f"views rejected {pct(r['unknown_rejected'])} of {r['n_unknown']}, accuracy on the accepted known "
            f"views {acc}"
        )
    if ev.skipped:
        lines.append(f"rows skipped: {len(ev.skipped)} (listed on stderr)")
    return "\n".join(lines)


def run_evaluate(args: argparse.Namespace) -> int:
    """Runs ``eigview evaluate``; returns 0, or 1 when rows were skipped."""
    check_outputs([("--json", args.json)], inputs=[("--model", args.model), *manifest_inputs(args)])
    from torch_eigview.io.model import load_model

    device = resolve_device(args.device)  # no CUDA: named before the model is read
    model = load_model(args.model)
    model.recognizer.to(device)  # the projection and the search; evaluate moves the views there
    meta = model.metadata
    if args.reject and not model.recognizer.rejects:
        raise ValueError(
            f"--reject needs a model with calibrated rejection (eigview fit without --no-reject); "
            f"{args.model} has none"
        )
    bad_lines: list[str] = []
    manifest = load_manifest(args, bad_lines)
    check_not_views([("--json", args.json)], manifest)
    skipped: list[dict[str, str]] = []
    for message in bad_lines:
        _skip(skipped, message)
    entries = list(manifest)
    if args.exclude_seeds:
        from torch_eigview.geometry.angles import wrap_angle

        if "seed_azimuths" not in meta:
            raise ValueError(
                f"--exclude-seeds needs the seed azimuths that eigview fit records; {args.model} has none"
            )
        seeds = [float(a) for a in meta["seed_azimuths"]]
        entries = [e for e in entries if not any(abs(wrap_angle(e.azimuth - a)) <= 1e-6 for a in seeds)]
        if not entries:
            raise ValueError(
                f"--exclude-seeds leaves no view of {manifest.name}: every view lies at a seed azimuth "
                f"({', '.join(f'{a:g}' for a in seeds)} degrees) of {args.model}"
            )
    ev = evaluate(
        model,
        entries,
        skipped=skipped,
        interpolate_pose=args.pose == "interpolate",
        reject=args.reject,
    )
    for row in ev.skipped:
        print(f"eigview evaluate: skipped {escape(row['row'])}: {escape(row['error'])}", file=sys.stderr)
    print(format_evaluation(ev, f"eigview evaluate: {args.model} on {manifest.name}"))
    if args.json:
        write_json(args.json, {**ev.to_json(), "model": args.model, "manifest": manifest.name})
    return 1 if ev.skipped else 0
