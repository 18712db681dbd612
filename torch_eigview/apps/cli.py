"""The ``eigview`` command.

``eigview coil --root DIR --alpha 5 ...`` runs the paper's COIL experiment (Fig. 4(b))
on a folder of ``obj{O}__{P}.png`` images and prints a per-object accuracy table.
``eigview export --model FILE --out model.onnx [--recognizer]`` writes a saved model as
ONNX; ``eigview predict --onnx model.onnx IMAGES...`` recognizes images with onnxruntime.

Torch-using modules are imported inside the subcommands: ``predict`` never imports torch.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from collections.abc import Callable, Sequence
from functools import partial
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from torch_eigview.apps.experiment import CoilResult

__all__ = ["main"]

MIN_OPSET = 18  # what torch_eigview.io.onnx exports
# Image side of the rendered demo and synth scenes: memory grows with its square.
SIZE_LIMIT = ("EIGVIEW_MAX_IMAGE_SIDE", 512)


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


def _word_or_float(text: str, word: str, message: str) -> float | str:
    """``word`` itself, or ``text`` as a float; ``message`` is the argparse error otherwise."""
    if text == word:
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(message) from None


def _finite(flag: str) -> Callable[[str], float]:
    """An argparse type: a finite number, the error naming ``flag`` (never an internal name)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{flag} must be a finite number, got {text!r}")
        return value

    return parse


def _bounded_int(flag: str, minimum: int, limit: tuple[str, int] | None = None) -> Callable[[str], int]:
    """An argparse type: an int >= ``minimum`` and at most ``limit`` (an environment variable
    that raises it, and its default), the error naming ``flag``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} must be an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{flag}={value} must be >= {minimum}")
        if limit is not None:
            from torch_eigview.check import check_limit  # imports torch: not on predict's path

            try:
                check_limit(value, flag, "pixels per image side", *limit)
            except ValueError as exc:
                raise argparse.ArgumentTypeError(str(exc)) from None
        return value

    return parse


def _opset(text: str) -> int:
    import onnx

    newest = onnx.defs.onnx_opset_version()
    value = _bounded_int("--opset", MIN_OPSET)(text)
    if value > newest:
        # The exporter would silently write another opset than the one asked for.
        raise argparse.ArgumentTypeError(
            f"--opset={value} must be at most {newest}, the newest opset of the installed onnx {onnx.__version__}"
        )
    return value


def _elevation(text: str) -> float | str:
    return _word_or_float(text, "auto", f"--elevation must be 'auto' or degrees, got {text!r}")


def _objects(text: str) -> list[int]:
    from torch_eigview.datasets.coil import parse_object_spec

    try:
        return parse_object_spec(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _gamma(text: str) -> float | str:
    return _word_or_float(text, "median", f"--gamma must be a number > 0 or 'median', got {text!r}")


def _add_coil(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    coil = sub.add_parser("coil", help="the COIL recognition experiment (paper Fig. 4(b))")
    coil.add_argument("--root", required=True, help="folder of obj{O}__{P}.png images (COIL-20 or COIL-100)")
    coil.add_argument(
        "--alpha", type=_finite("--alpha"), required=True, help="angle between seed views, degrees"
    )
    coil.add_argument(
        "--center", type=_finite("--center"), default=0.0, help="pose of the first seed view, degrees"
    )
    coil.add_argument("--views", type=int, default=2, choices=(2, 3), help="seed views per object")
    coil.add_argument(
        "--synth",
        type=_finite("--synth"),
        nargs=3,
        default=(-20.0, 20.0, 1.0),
        metavar=("START", "STOP", "STEP"),
        help="synthesized angles for two seed views; each further seed extends the range by alpha",
    )
    coil.add_argument(
        "--test", type=_finite("--test"), nargs=2, default=(-45.0, 45.0), metavar=("START", "STOP")
    )
    coil.add_argument("--components", type=_components, default=15, help="k, or an energy fraction in (0, 1)")
    coil.add_argument("--method", choices=("nvs", "sparse", "dense"), default="nvs")
    coil.add_argument("--objects", type=_objects, default=None, help="e.g. 1-20 or 1,3,5-7 (default: all)")
    coil.add_argument(
        "--flow", choices=("tvl1", "ilk"), default="tvl1", help="optical flow for correspondences"
    )
    coil.add_argument(
        "--elevation", type=_elevation, default="auto", help="camera elevation, degrees, or 'auto' (default)"
    )
    coil.add_argument(
        "--blend",
        choices=("linear", "nearest"),
        default="linear",
        help="pixels both seeds see: cross-dissolve by angle, or the nearer seed alone",
    )
    coil.add_argument(
        "--silhouette",
        action="store_true",
        help="silhouette-aware sampling: only the seeds' foreground enters a synthesized pixel",
    )
    coil.add_argument(
        "--pose-unit",
        choices=("auto", "index", "degrees"),
        default="auto",
        help="file pose P: an index (COIL-20, 5*P degrees), degrees (COIL-100), or auto (default)",
    )
    coil.add_argument("--no-extent", action="store_true", help="do not size-normalize synthesized views")
    coil.add_argument("--no-unit-norm", action="store_true", help="do not L2-normalize views")
    coil.add_argument("--json", metavar="FILE", help="write the results as JSON")
    coil.add_argument("--save", metavar="FILE", help="write the fitted eigenspace and gallery")
    coil.add_argument(
        "--kernel",
        choices=("rbf", "poly", "cosine", "linear"),
        default=None,
        help="kernel PCA instead of the linear eigenspace (not with --save)",
    )
    coil.add_argument(
        "--gamma", type=_gamma, default=None, help="kernel gamma, or 'median' (rbf; default 1/N)"
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="eigview", description=__doc__.splitlines()[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="command", required=True)
    _add_coil(sub)
    _add_export_and_predict(sub)
    demo = sub.add_parser("demo", help="the embedded demo: Fig. 2 on five rendered synthetic objects")
    demo.add_argument(
        "--alpha", type=_finite("--alpha"), default=10.0, help="angle between the two seed views, degrees"
    )
    demo.add_argument(
        "--size", type=_bounded_int("--size", 1, SIZE_LIMIT), default=64, help="image side in pixels"
    )
    demo.add_argument("--correspondences", choices=("flow", "exact"), default="flow")
    demo.add_argument("--png", default="eigview_demo.png", help="figure to write ('' for none)")
    demo.add_argument("--json", metavar="FILE", help="write the results as JSON")
    synth = sub.add_parser(
        "synth", help="the Fig. 2 protocol per camera model (orthographic, affine, perspective)"
    )
    synth.add_argument("--camera", choices=("orthographic", "affine", "perspective"), default="orthographic")
    synth.add_argument(
        "--alpha", type=_finite("--alpha"), nargs="+", default=[5.0, 10.0, 15.0, 20.0, 30.0], help="degrees"
    )
    synth.add_argument("--views", type=int, nargs="+", choices=(2, 3), default=[2, 3], help="seed views N")
    synth.add_argument(
        "--size", type=_bounded_int("--size", 1, SIZE_LIMIT), default=64, help="image side in pixels"
    )
    synth.add_argument("--correspondences", choices=("flow", "exact"), default="flow")
    synth.add_argument("--shapes", default=None, help="comma-separated objects (default: all five)")
    synth.add_argument("--json", metavar="FILE", help="write the results as JSON")
    # Listed for --help; main() hands its arguments to torch_eigview.apps.bench unparsed.
    sub.add_parser("bench", help="benchmarks (warp, eigen step, GEMM, scaling): eigview bench --help")
    return parser


def _add_export_and_predict(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from torch_eigview.apps.predict import add_arguments

    export = sub.add_parser("export", help="write a saved model (eigview coil --save) as ONNX")
    export.add_argument("--model", required=True, metavar="FILE", help="file written by eigview coil --save")
    export.add_argument("--out", required=True, metavar="FILE", help="the .onnx file to write")
    export.add_argument(
        "--recognizer",
        action="store_true",
        help="export the whole recognizer (images -> label, pose, distance), not just the projection",
    )
    export.add_argument("--opset", type=_opset, default=MIN_OPSET, help="ONNX opset (>= 18)")
    predict = sub.add_parser("predict", help="recognize images with an exported ONNX recognizer (no torch)")
    add_arguments(predict)


def _run_export(args: argparse.Namespace) -> int:
    from torch_eigview.io.checkpoint import load_recognizer
    from torch_eigview.io.onnx import export_projection, export_recognizer

    recognizer, _ = load_recognizer(args.model)
    if args.recognizer:
        info = export_recognizer(recognizer, args.out, opset_version=args.opset)
    else:
        info = export_projection(recognizer.projection, args.out, opset_version=args.opset)
    c, h, w = info.image_shape
    print(
        f"wrote {args.out}: {info.kind}, images (B, {c}, {h}, {w}) float32, k={info.n_components}, "
        f"unit_norm={info.unit_norm}" + (f", {len(info.label_names)} labels" if info.label_names else "")
    )
    return 0


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
    from torch_eigview.apps.experiment import CoilExperiment
    from torch_eigview.datasets.coil import CoilFolder
    from torch_eigview.io.checkpoint import save_recognizer
    from torch_eigview.synthesis import SynthesisOptions

    folder = CoilFolder(args.root, pose_unit=args.pose_unit)
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
        synthesis=SynthesisOptions(
            flow=args.flow,
            elevation=args.elevation,
            extent=not args.no_extent,
            blend=args.blend,
            silhouette=args.silhouette,
        ),
        kernel=args.kernel,
        gamma=args.gamma,
    )
    if args.kernel and args.save:
        raise ValueError("--save writes a linear eigenspace only: it cannot be used with --kernel")
    progress = None
    if sys.stderr.isatty():
        from tqdm import tqdm

        progress = partial(tqdm, desc=f"{args.method} objects", unit="obj")
    result = experiment.run(folder, progress=progress)
    title = f"COIL {args.method}: alpha={args.alpha:g}, {args.views} seed views, center={args.center:g}"
    if args.kernel:
        title += f", kernel PCA ({args.kernel}, gamma={getattr(result.recognizer.projection, 'gamma', float('nan')):g})"
    print(format_table(result, title))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result.to_json(), fh, indent=2)
    if args.save:
        meta = {"command": "coil", "alpha": args.alpha, "method": args.method, "accuracy": result.accuracy}
        save_recognizer(args.save, result.recognizer, meta)
    return 0


def _run_demo(args: argparse.Namespace) -> int:
    from torch_eigview.apps.demo import run_demo

    record = run_demo(args.png or None, args.alpha, size=args.size, correspondences=args.correspondences)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(record, fh, indent=2, default=str)
    return 0


def _run_synth(args: argparse.Namespace) -> int:
    from torch_eigview.apps.demo import run_synth
    from torch_eigview.datasets import SHAPES

    shapes = SHAPES if args.shapes is None else tuple(args.shapes.split(","))
    unknown = sorted(set(shapes) - set(SHAPES))
    if unknown:
        raise ValueError(f"--shapes has unknown shape(s) {unknown}; known: {', '.join(SHAPES)}")
    record = run_synth(
        args.camera,
        args.alpha,
        args.views,
        size=args.size,
        correspondences=args.correspondences,
        shapes=shapes,
    )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(record, fh, indent=2, default=str)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``eigview``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["bench"]:
        from torch_eigview.apps.bench import main as bench_main

        return bench_main(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings():  # restores the formatter for in-process callers
        warnings.showwarning = _show_warning
        return _dispatch(parser, args)


def _show_warning(message: Warning | str, category: type[Warning], *_: object, **__: object) -> None:
    """Warnings as one line on stderr, like the errors (no source line of the package)."""
    print(f"eigview: warning: {message}", file=sys.stderr)


def _dispatch(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    try:
        if args.command == "coil":
            return _run_coil(args)
        if args.command == "export":
            return _run_export(args)
        if args.command == "demo":
            return _run_demo(args)
        if args.command == "synth":
            return _run_synth(args)
        if args.command == "predict":
            from torch_eigview.apps.predict import run

            return run(args)
    except ValueError as exc:
        parser.exit(2, f"eigview: error: {exc}\n")
    return 1


if __name__ == "__main__":
    sys.exit(main())
