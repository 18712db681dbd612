"""The ``eigview`` command.

``eigview coil --root DIR --alpha 5 ...`` runs the paper's COIL experiment (Fig. 4(b))
on a folder of ``obj{O}__{P}.png`` images and prints a per-object accuracy table.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from functools import partial

from torch_eigview.data import CoilFolder, parse_object_spec
from torch_eigview.experiment import CoilExperiment, CoilResult
from torch_eigview.io import save_recognizer
from torch_eigview.synthesis import SynthesisOptions

__all__ = ["main"]


def _components(text: str) -> int | float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--components must be an int or a fraction in (0, 1), got {text!r}"
        ) from None
    if value.is_integer() and value >= 1:
        return int(value)
    if 0 < value < 1:
        return value
    raise argparse.ArgumentTypeError(
        f"--components must be an int >= 1 or a fraction in (0, 1), got {text!r}"
    )


def _elevation(text: str) -> float | str:
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--elevation must be 'auto' or degrees, got {text!r}") from None


def _objects(text: str) -> list[int]:
    try:
        return parse_object_spec(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="eigview", description=__doc__.splitlines()[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="command", required=True)
    coil = sub.add_parser("coil", help="the COIL recognition experiment (paper Fig. 4(b))")
    coil.add_argument("--root", required=True, help="folder of obj{O}__{P}.png images (COIL-20 or COIL-100)")
    coil.add_argument("--alpha", type=float, required=True, help="angle between seed views, degrees")
    coil.add_argument("--center", type=float, default=0.0, help="pose of the first seed view, degrees")
    coil.add_argument("--views", type=int, default=2, choices=(2, 3), help="seed views per object")
    coil.add_argument(
        "--synth", type=float, nargs=3, default=(-20.0, 20.0, 1.0), metavar=("START", "STOP", "STEP")
    )
    coil.add_argument("--test", type=float, nargs=2, default=(-45.0, 45.0), metavar=("START", "STOP"))
    coil.add_argument("--components", type=_components, default=15, help="k, or an energy fraction in (0, 1)")
    coil.add_argument("--method", choices=("nvs", "sparse", "dense"), default="nvs")
    coil.add_argument("--objects", type=_objects, default=None, help="e.g. 1-20 or 1,3,5-7 (default: all)")
    coil.add_argument(
        "--flow", choices=("tvl1", "ilk"), default="tvl1", help="optical flow for correspondences"
    )
    coil.add_argument(
        "--elevation", type=_elevation, default="auto", help="camera elevation, degrees, or 'auto' (default)"
    )
    coil.add_argument("--no-extent", action="store_true", help="do not size-normalize synthesized views")
    coil.add_argument("--no-unit-norm", action="store_true", help="do not L2-normalize views")
    coil.add_argument("--json", metavar="FILE", help="write the results as JSON")
    coil.add_argument("--save", metavar="FILE", help="write the fitted eigenspace and gallery")
    return parser


def format_table(result: CoilResult, title: str) -> str:
    """The per-object accuracy table of Fig. 4(b), then the total."""
    lines = [title, f"{'object':>8} {'accuracy (%)':>13}"]
    lines += [f"{'O' + str(obj):>8} {acc:13.2f}" for obj, acc in result.per_object.items()]
    lines.append(f"{'Total':>8} {result.accuracy:13.2f}")
    lines.append(
        f"test images {result.n_test}, gallery views {result.n_train_views}, "
        f"pose MAE (correct matches) {result.pose_mae_deg:.2f} deg"
    )
    lines.append("seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in result.seconds.items()))
    return "\n".join(lines)


def _run_coil(args: argparse.Namespace) -> int:
    folder = CoilFolder(args.root)
    experiment = CoilExperiment(
        alpha=args.alpha,
        center=args.center,
        views=args.views,
        synth=tuple(args.synth),
        test=tuple(args.test),
        components=args.components,
        method=args.method,
        objects=args.objects,
        unit_norm=not args.no_unit_norm,
        synthesis=SynthesisOptions(flow=args.flow, elevation=args.elevation, extent=not args.no_extent),
    )
    progress = None
    if sys.stderr.isatty():
        from tqdm import tqdm

        progress = partial(tqdm, desc=f"{args.method} objects", unit="obj")
    result = experiment.run(folder, progress=progress)
    title = f"COIL {args.method}: alpha={args.alpha:g}, {args.views} seed views, center={args.center:g}"
    print(format_table(result, title))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result.to_json(), fh, indent=2)
    if args.save:
        meta = {"command": "coil", "alpha": args.alpha, "method": args.method, "accuracy": result.accuracy}
        save_recognizer(args.save, result.recognizer, meta)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``eigview``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "coil":
            return _run_coil(args)
    except ValueError as exc:
        parser.exit(2, f"eigview: error: {exc}\n")
    return 1


if __name__ == "__main__":
    sys.exit(main())
