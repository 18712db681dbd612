"""The ``eigview`` command.

``eigview coil --root DIR --alpha 5 ...`` runs the paper's COIL experiment (Fig. 4(b))
on a folder of ``obj{O}__{P}.png`` images and prints a per-object accuracy table.
``eigview export --model FILE --out model.onnx [--recognizer]`` writes a saved model as
ONNX; ``eigview predict --onnx model.onnx IMAGES...`` recognizes images with onnxruntime.

Torch-using modules are imported inside the subcommands: ``predict`` never imports torch.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from typing import TYPE_CHECKING, TypeVar

from torch_eigview.files import check_outputs, write_json

if TYPE_CHECKING:
    from torch_eigview.apps.experiment import CoilResult

__all__ = ["main", "progress_bar"]

T = TypeVar("T")


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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="eigview", description=__doc__.splitlines()[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="command", required=True)
    coil = sub.add_parser("coil", help="the COIL recognition experiment (paper Fig. 4(b))")
    coil.add_argument(
        "--root",
        default=None,
        help="folder of obj{O}__{P}.png images (COIL-20 or COIL-100); default: coil-20-proc/ in "
        "$TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc beside the checkout",
    )
    coil.add_argument(
        "--alpha",
        type=float,
        default=None,
        help="angle between seed views, degrees (required without --seeds)",
    )
    coil.add_argument("--center", type=float, default=0.0, help="pose of the first seed view, degrees")
    coil.add_argument(
        "--views", type=int, default=None, choices=(2, 3), help="seed views per object (default 2)"
    )
    coil.add_argument(
        "--seeds",
        type=int,
        default=None,
        metavar="M",
        help="the full circle: M seed views 360/M degrees apart from --center, every sector synthesized, "
        "every other pose tested (instead of --alpha and --views)",
    )
    coil.add_argument(
        "--pose",
        choices=("nearest", "interpolate"),
        default="nearest",
        help="the reported pose: the nearest gallery view's, or interpolated on the appearance "
        "manifold between it and its neighbours (Murase and Nayar); default nearest",
    )
    coil.add_argument(
        "--dense-step",
        type=float,
        default=None,
        metavar="S",
        help="with --seeds and --method dense: real views every S degrees (default about 180/M)",
    )
    coil.add_argument(
        "--synth",
        type=float,
        nargs=3,
        default=(-20.0, 20.0, 1.0),
        metavar=("START", "STOP", "STEP"),
        help="synthesized angles for two seed views; each further seed extends the range by alpha",
    )
    coil.add_argument("--test", type=float, nargs=2, default=(-45.0, 45.0), metavar=("START", "STOP"))
    coil.add_argument("--components", type=_components, default=15, help="k, or an energy fraction in (0, 1)")
    coil.add_argument("--method", choices=("nvs", "sparse", "dense"), default="nvs")
    coil.add_argument("--objects", type=_objects, default=None, help="e.g. 1-20 or 1,3,5-7 (default: all)")
    coil.add_argument(
        "--flow",
        choices=("tvl1", "ilk", "rows"),
        default="tvl1",
        help="correspondences: optical flow, or semi-global matching along rows (rows)",
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
    _add_export_and_predict(sub)
    _add_quiet(coil)
    demo = sub.add_parser("demo", help="the embedded demo: Fig. 2 on five rendered synthetic objects")
    demo.add_argument("--alpha", type=float, default=10.0, help="angle between the two seed views, degrees")
    demo.add_argument("--size", type=int, default=64, help="image side in pixels")
    demo.add_argument("--correspondences", choices=("flow", "exact"), default="flow")
    demo.add_argument("--png", default="eigview_demo.png", help="figure to write ('' for none)")
    demo.add_argument("--json", metavar="FILE", help="write the results as JSON")
    _add_quiet(demo)
    synth = sub.add_parser(
        "synth", help="the Fig. 2 protocol per camera model (orthographic, affine, perspective)"
    )
    synth.add_argument("--camera", choices=("orthographic", "affine", "perspective"), default="orthographic")
    synth.add_argument(
        "--alpha", type=float, nargs="+", default=[5.0, 10.0, 15.0, 20.0, 30.0], help="degrees"
    )
    synth.add_argument("--views", type=int, nargs="+", choices=(2, 3), default=[2, 3], help="seed views N")
    synth.add_argument("--size", type=int, default=64, help="image side in pixels")
    synth.add_argument("--correspondences", choices=("flow", "exact"), default="flow")
    synth.add_argument("--shapes", default=None, help="comma-separated objects (default: all five)")
    synth.add_argument("--json", metavar="FILE", help="write the results as JSON")
    _add_quiet(synth)
    # Listed for --help; main() hands its arguments to torch_eigview.apps.bench unparsed.
    sub.add_parser("bench", help="benchmarks (warp, eigen step, GEMM, scaling): eigview bench --help")
    return parser


def _add_quiet(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--quiet", action="store_true", help="no progress bar (there is none when stderr is not a terminal)"
    )


def progress_bar(quiet: bool, desc: str, unit: str) -> Callable[[Iterable[T]], Iterable[T]] | None:
    """A tqdm wrapper for a command's main loop, or None when ``quiet`` or stderr is no terminal.

    The bar goes to stderr, so it shows whenever a person watches the command, even with
    stdout redirected to a file; a log or a pipe (stderr not a TTY) gets no bar.
    ``leave=False``: the bar disappears when done, and the results print below it alone.
    """
    if quiet or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return partial(tqdm, desc=desc, unit=unit, leave=False, file=sys.stderr)


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
    export.add_argument("--opset", type=int, default=18, help="ONNX opset (>= 18)")
    predict = sub.add_parser("predict", help="recognize images with an exported ONNX recognizer (no torch)")
    add_arguments(predict)


def _run_export(args: argparse.Namespace) -> int:
    from torch_eigview.io.checkpoint import load_recognizer
    from torch_eigview.io.onnx import export_projection, export_recognizer

    check_outputs([("--out", args.out)], inputs=[("--model", args.model)])
    recognizer, _ = load_recognizer(args.model)  # verifies the model's checksum
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


def _check_circle_flags(args: argparse.Namespace) -> None:
    """The flag combinations of the full circle that need no folder to refuse."""
    if args.seeds is None:
        if args.alpha is None:
            raise ValueError("--alpha is required (the angle between seed views), unless --seeds is given")
        if args.dense_step is not None:
            raise ValueError(f"--dense-step {args.dense_step:g} needs --seeds (the full circle)")
        return
    if args.seeds < 2:
        raise ValueError(f"--seeds={args.seeds} must be >= 2")
    if args.views is not None:
        raise ValueError(
            f"--seeds {args.seeds} places its own seed views: it cannot take --views {args.views}"
        )
    if args.alpha is not None and abs(args.alpha - 360.0 / args.seeds) > 1e-9:
        raise ValueError(
            f"--alpha {args.alpha:g} contradicts --seeds {args.seeds} (seeds 360/{args.seeds} = "
            f"{360.0 / args.seeds:g} degrees apart); leave --alpha out"
        )
    if args.dense_step is not None and args.method != "dense":
        raise ValueError(f"--dense-step {args.dense_step:g} needs --method dense, got --method {args.method}")


def _run_coil(args: argparse.Namespace) -> int:
    from torch_eigview.apps.experiment import CoilExperiment
    from torch_eigview.datasets.coil import CoilFolder, find_coil_root
    from torch_eigview.io.checkpoint import save_recognizer
    from torch_eigview.synthesis import SynthesisOptions

    check_outputs([("--json", args.json), ("--save", args.save)], inputs=[("--root", args.root)])
    folder = CoilFolder(find_coil_root(args.root))
    _check_circle_flags(args)
    experiment = CoilExperiment(
        alpha=args.alpha if args.alpha is not None else 360.0 / args.seeds,
        center=args.center,
        views=args.views or 2,
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
        seeds=args.seeds,
        dense_step=args.dense_step,
        interpolate_pose=args.pose == "interpolate",
    )
    if args.seeds is not None:
        experiment.circle(folder, args.objects, names=("--seeds", "--dense-step"))
    if args.kernel and args.save:
        raise ValueError("--save writes a linear eigenspace only: it cannot be used with --kernel")
    result = experiment.run(folder, progress=progress_bar(args.quiet, f"{args.method} objects", "obj"))
    if args.seeds is None:
        title = (
            f"COIL {args.method}: alpha={args.alpha:g}, {experiment.views} seed views, center={args.center:g}"
        )
    else:
        title = f"COIL {args.method}: full circle, {args.seeds} seed views from center={args.center:g}"
    if args.kernel:
        title += f", kernel PCA ({args.kernel}, gamma={getattr(result.recognizer.projection, 'gamma', float('nan')):g})"
    print(format_table(result, title))
    if args.json:
        write_json(args.json, result.to_json())
    if args.save:
        meta = {"command": "coil", "alpha": args.alpha, "method": args.method, "accuracy": result.accuracy}
        save_recognizer(args.save, result.recognizer, meta)
    return 0


def _run_demo(args: argparse.Namespace) -> int:
    from torch_eigview.apps.demo import run_demo

    check_outputs([("--png", args.png), ("--json", args.json)])
    record = run_demo(
        args.png or None,
        args.alpha,
        size=args.size,
        correspondences=args.correspondences,
        progress=progress_bar(args.quiet, "demo objects", "obj"),
    )
    if args.json:
        write_json(args.json, record, default=str)
    return 0


def _run_synth(args: argparse.Namespace) -> int:
    from torch_eigview.apps.demo import run_synth
    from torch_eigview.datasets import SHAPES

    check_outputs([("--json", args.json)])
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
        progress=progress_bar(args.quiet, f"synth {args.camera}", "run"),
    )
    if args.json:
        write_json(args.json, record, default=str)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``eigview``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["bench"]:
        from torch_eigview.apps.bench import main as bench_main

        return bench_main(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
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
    except (
        ValueError,
        OSError,
        ImportError,
    ) as exc:  # OSError: an output that failed to write (disk full); ImportError: a missing extra, whose message names the pip install
        parser.exit(2, f"eigview: error: {exc}\n")
    return 1


if __name__ == "__main__":
    sys.exit(main())
