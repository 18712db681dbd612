"""The ``eigview`` command.

``eigview coil --root DIR --alpha 5 ...`` runs the paper's COIL experiment (Fig. 4(b))
on a folder of ``obj{O}__{P}.png`` images and prints a per-object accuracy table.
``eigview fit --manifest views.csv --seeds 0 10 --out model.pt`` fits a recognizer from the
seed views of any objects; ``eigview evaluate --model model.pt --manifest views.csv`` scores it.
``eigview export --model FILE --out model.onnx [--recognizer]`` writes a saved model as
ONNX; ``eigview predict --onnx model.onnx IMAGES...`` recognizes images with onnxruntime
(``--model model.pt``: with torch).

Torch-using modules are imported inside the subcommands: ``predict`` never imports torch.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING

from torch_eigview.apps.cli_args import (
    MIN_OPSET,
    add_quiet,
    add_threads,
    bounded_int_arg,
    finite_arg,
    opset_arg,
    progress_bar,
)
from torch_eigview.apps.coil_command import add_coil_command, run_coil
from torch_eigview.apps.evaluate_command import add_evaluate_command, run_evaluate
from torch_eigview.apps.fit_command import add_fit_command, run_fit
from torch_eigview.files import check_outputs, write_json

if TYPE_CHECKING:
    pass

__all__ = ["main"]


# Image side of the rendered demo and synth scenes: memory grows with its square.
SIZE_LIMIT = ("EIGVIEW_MAX_IMAGE_SIDE", 512)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="eigview", description=__doc__.splitlines()[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="command", required=True)
    add_coil_command(sub)
    add_fit_command(sub)
    add_evaluate_command(sub)
    _add_export_and_predict(sub)
    demo = sub.add_parser("demo", help="the embedded demo: Fig. 2 on five rendered synthetic objects")
    demo.add_argument(
        "--alpha", type=finite_arg("--alpha"), default=10.0, help="angle between the two seed views, degrees"
    )
    demo.add_argument(
        "--size",
        type=bounded_int_arg("--size", 2, SIZE_LIMIT),
        default=64,
        help="image side in pixels (>= 2)",
    )
    demo.add_argument("--correspondences", choices=("flow", "exact"), default="flow")
    demo.add_argument("--png", default="eigview_demo.png", help="figure to write ('' for none)")
    demo.add_argument("--json", metavar="FILE", help="write the results as JSON")
    add_quiet(demo)
    add_threads(demo)
    synth = sub.add_parser(
        "synth", help="the Fig. 2 protocol per camera model (orthographic, affine, perspective)"
    )
    synth.add_argument("--camera", choices=("orthographic", "affine", "perspective"), default="orthographic")
    synth.add_argument(
        "--alpha",
        type=finite_arg("--alpha"),
        nargs="+",
        default=[5.0, 10.0, 15.0, 20.0, 30.0],
        help="degrees",
    )
    synth.add_argument("--views", type=int, nargs="+", choices=(2, 3), default=[2, 3], help="seed views N")
    synth.add_argument(
        "--size",
        type=bounded_int_arg("--size", 2, SIZE_LIMIT),
        default=64,
        help="image side in pixels (>= 2)",
    )
    synth.add_argument("--correspondences", choices=("flow", "exact"), default="flow")
    synth.add_argument("--shapes", default=None, help="comma-separated objects (default: all five)")
    for flag, choices, what in (
        (
            "--background",
            ("black", "textured"),
            "black (the paper's) or a coloured, textured backdrop and ground",
        ),
        (
            "--masks",
            ("given", "estimated"),
            "textured: the renderer's masks or ones estimated from the border",
        ),
    ):
        synth.add_argument(flag, choices=choices, default=choices[0], help=f"default {choices[0]}; {what}")
    synth.add_argument("--json", metavar="FILE", help="write the results as JSON")
    add_quiet(synth)
    add_threads(synth)
    # Listed for --help; main() hands its arguments to torch_eigview.apps.bench unparsed.
    sub.add_parser("bench", help="benchmarks (warp, eigen step, GEMM, scaling): eigview bench --help")
    return parser


def _add_export_and_predict(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from torch_eigview.apps.predict import add_arguments

    export = sub.add_parser("export", help="write a saved model (eigview coil --save) as ONNX")
    export.add_argument(
        "--model", required=True, metavar="FILE", help="file written by eigview fit or eigview coil --save"
    )
    export.add_argument("--out", required=True, metavar="FILE", help="the .onnx file to write")
    export.add_argument(
        "--recognizer",
        action="store_true",
        help="export the whole recognizer (images -> label, pose, distance), not just the projection",
    )
    export.add_argument("--opset", type=opset_arg, default=MIN_OPSET, help="ONNX opset (>= 18)")
    predict = sub.add_parser(
        "predict", help="recognize images with an exported ONNX recognizer (no torch) or a model file"
    )
    add_arguments(predict)


def _run_export(args: argparse.Namespace) -> int:
    from torch_eigview.apps.view_inputs import model_preprocessing
    from torch_eigview.io.checkpoint import load_recognizer
    from torch_eigview.io.onnx import export_projection, export_recognizer

    check_outputs([("--out", args.out)], inputs=[("--model", args.model)])
    recognizer, meta = load_recognizer(args.model)  # verifies the model's checksum
    if args.recognizer:
        # An eigview fit model's preprocessing goes into the graph's metadata, for predict.
        prep = model_preprocessing(recognizer, meta, args.model) if "preprocessing" in meta else None
        info = export_recognizer(recognizer, args.out, opset_version=args.opset, preprocessing=prep)
    else:
        info = export_projection(recognizer.projection, args.out, opset_version=args.opset)
    c, h, w = info.image_shape
    print(
        f"wrote {args.out}: {info.kind}, images (B, {c}, {h}, {w}) float32, k={info.n_components}, "
        f"unit_norm={info.unit_norm}" + (f", {len(info.label_names)} labels" if info.label_names else "")
    )
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
    if args.masks != "given" and args.background != "textured":  # black views have no mask to estimate
        raise ValueError(
            f"--masks {args.masks} goes with --background textured, got --background {args.background}"
        )
    record = run_synth(
        args.camera,
        args.alpha,
        args.views,
        size=args.size,
        correspondences=args.correspondences,
        shapes=shapes,
        progress=progress_bar(args.quiet, f"synth {args.camera}", "run"),
        background=args.background,
        masks=args.masks,
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
    with warnings.catch_warnings():  # restores the formatter for in-process callers
        warnings.showwarning = _show_warning
        return _dispatch(parser, args)


def _show_warning(message: Warning | str, category: type[Warning], *_: object, **__: object) -> None:
    """Warnings as one line on stderr, like the errors (no source line of the package)."""
    print(f"eigview: warning: {message}", file=sys.stderr)


def _dispatch(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    try:
        runs = {
            "coil": run_coil,
            "fit": run_fit,
            "evaluate": run_evaluate,
            "demo": _run_demo,
            "synth": _run_synth,
        }
        if args.command in runs:
            from torch_eigview.scale.thread_policy import threads

            with threads(args.threads):  # the policy, restored on return (main() may be called)
                return runs[args.command](args)
        if args.command == "export":
            return _run_export(args)
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
