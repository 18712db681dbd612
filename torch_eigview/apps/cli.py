"""The ``eigview`` command: object recognition from a few views per object.

Each subcommand is a module of its own (``coil_command``, ``fit_command``,
``evaluate_command``, ``predict``, ``demo``); this one parses, dispatches and turns a
``ValueError`` into one ``eigview: error:`` line and exit status 2. Torch-using modules
are imported inside the subcommands: ``predict --onnx`` never imports torch.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Mapping, Sequence

from torch_eigview.apps.cli_args import (
    MIN_OPSET,
    ArgumentParser,
    HelpFormatter,
    add_quiet,
    add_threads,
    angle_arg,
    bounded_int_arg,
    opset_arg,
    progress_bar,
)
from torch_eigview.apps.coil_command import add_coil_command, run_coil
from torch_eigview.apps.evaluate_command import add_evaluate_command, run_evaluate
from torch_eigview.apps.fit_command import add_fit_command, run_fit
from torch_eigview.config import DEFAULTS, config_context
from torch_eigview.environment import package_version
from torch_eigview.files import check_outputs, write_json
from torch_eigview.parse import parse_int

__all__ = ["main"]


# Image side of the rendered demo: memory grows with its square.
SIZE_LIMIT = "max_image_side"


DESCRIPTION = """\
Object recognition and pose from two or three views per object: the views between and
beyond them are synthesized (a turntable's rotation), one appearance eigenspace is fitted
over every object's views, and new images are recognized by their nearest gallery view.

  eigview demo                                           the paper's Fig. 2 on rendered objects
  eigview fit --manifest views.csv --seeds 0 10 --out model.pt     your own objects
  eigview evaluate --model model.pt --manifest views.csv           score a model
  eigview predict --model model.pt photo.png                       recognize images
  eigview export --model model.pt --out model.onnx --recognizer    ONNX for onnxruntime
  eigview coil --folder coil-20-proc --alpha 10                    the paper's COIL-20 protocol
"""


def build_parser() -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = ArgumentParser(
        prog="eigview", description=DESCRIPTION, formatter_class=HelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_coil_command(sub)
    add_fit_command(sub)
    add_evaluate_command(sub)
    _add_export_and_predict(sub)
    demo = sub.add_parser(
        "demo",
        help="the embedded demo: the paper's Fig. 2 on five rendered objects",
        description="Five textured objects rendered at 0 and alpha degrees, the views over -20..20 "
        "synthesized, one eigenspace of 15 components, and 450 rendered test views recognized.",
        formatter_class=HelpFormatter,
    )
    demo.add_argument(
        "--alpha", type=angle_arg("--alpha"), default=10.0, help="angle between the two seed views, degrees"
    )
    demo.add_argument(
        "--size",
        type=bounded_int_arg("--size", 2, SIZE_LIMIT),
        default=64,
        help="image side in pixels, >= 2",
    )
    demo.add_argument(
        "--png", default="eigview_demo.png", metavar="FILE", help="figure to write ('' for none)"
    )
    demo.add_argument("--json", metavar="FILE", help="write the results as JSON")
    add_quiet(demo)
    add_threads(demo)
    return parser


def _add_export_and_predict(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from torch_eigview.apps.predict import add_arguments

    export = sub.add_parser(
        "export",
        help="write a model file as an ONNX graph, for onnxruntime",
        description="A model file of eigview fit or eigview coil --save as an ONNX graph: the projection "
        "(images -> eigenspace coordinates), or with --recognizer the whole recognizer (images -> label, "
        "pose, distance), its preprocessing in the graph's metadata.",
        formatter_class=HelpFormatter,
    )
    export.add_argument(
        "--model", required=True, metavar="FILE", help="file written by eigview fit or eigview coil --save"
    )
    export.add_argument("--out", required=True, metavar="FILE", help="the .onnx file to write")
    export.add_argument(
        "--recognizer",
        action="store_true",
        help="export the whole recognizer (images -> label, pose, distance), not just the projection",
    )
    export.add_argument("--opset", type=opset_arg, default=MIN_OPSET, help="ONNX opset, >= 18")
    predict = sub.add_parser(
        "predict",
        help="recognize images with a model file, or an exported ONNX recognizer (no torch)",
        description="Each image, prepared as the model records (size, channels, background), "
        "recognized: its label, pose and eigenspace distance, one line each.",
        formatter_class=HelpFormatter,
    )
    add_arguments(predict)


def _run_export(args: argparse.Namespace) -> int:
    from torch_eigview.io.model import load_model
    from torch_eigview.io.onnx import export_projection, export_recognizer

    check_outputs([("--out", args.out)], inputs=[("--model", args.model)])
    model = load_model(args.model)  # verifies the model's checksum
    if args.recognizer:
        # A recorded preprocessing (eigview fit's) goes into the graph's metadata, for predict.
        prep = model.preprocessing if "preprocessing" in model.metadata else None
        info = export_recognizer(model.recognizer, args.out, opset_version=args.opset, preprocessing=prep)
    else:
        info = export_projection(model.recognizer.projection, args.out, opset_version=args.opset)
    c, h, w = info.image_shape
    print(
        f"wrote {args.out}: {info.kind}, images (B, {c}, {h}, {w}) float32, k={info.n_components}, "
        f"unit_norm={info.unit_norm}" + (f", {len(info.label_names)} labels" if info.label_names else "")
    )
    return 0


def _run_demo(args: argparse.Namespace) -> int:
    from torch_eigview.apps.demo import run_demo
    from torch_eigview.check import check_alpha

    check_outputs([("--png", args.png), ("--json", args.json)])
    check_alpha(args.alpha, "--alpha")  # two seed views alpha apart: named before any rendering
    record = run_demo(
        args.png or None,
        args.alpha,
        size=args.size,
        progress=progress_bar(args.quiet, "demo objects", "obj"),
    )
    if args.json:
        write_json(args.json, record, default=str)
    return 0


def limits_from_environment(environ: Mapping[str, str] | None = None) -> dict[str, int]:
    """The limits of :mod:`torch_eigview.config` that ``EIGVIEW_MAX_VIEWS``,
    ``EIGVIEW_MAX_IMAGE_SIDE``, ``EIGVIEW_MAX_OBJECTS``, ``EIGVIEW_MAX_THREADS`` and
    ``EIGVIEW_MAX_MODEL_BYTES`` set (an empty one counts as unset): the only place the
    command reads the environment, besides the data home of
    :func:`~torch_eigview.datasets.get_data_home`.

    Raises:
        ValueError: a value that is not a positive integer; the message names the variable.
    """
    env = os.environ if environ is None else environ
    limits = {}
    for key in DEFAULTS:
        name = f"EIGVIEW_{key.upper()}"
        text = env.get(name, "").strip()
        if not text:
            continue
        if not (text.isascii() and text.isdigit() and int(text) >= 1):
            raise ValueError(f"environment variable {name}={text!r} must be a positive integer")
        limits[key] = int(text)
    return limits


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``eigview``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        limits = limits_from_environment()
    except ValueError as exc:
        parser.exit(2, f"eigview: error: {exc}\n")
    with config_context(**limits):  # the limits also bound what the arguments may ask for
        args = parser.parse_args(argv)
        with warnings.catch_warnings():  # restores the formatter for in-process callers
            warnings.showwarning = _show_warning
            return _dispatch(parser, args)


def _show_warning(message: Warning | str, category: type[Warning], *_: object, **__: object) -> None:
    """Warnings as one line on stderr, like the errors (no source line of the package)."""
    print(f"eigview: warning: {message}", file=sys.stderr)


def ranks_from_environment(environ: Mapping[str, str] | None = None) -> tuple[int, int]:
    """``(rank, world size)`` from torchrun's ``RANK`` and ``WORLD_SIZE`` (``(0, 1)`` when
    unset): with :func:`limits_from_environment`, what the command reads of its environment.

    Raises:
        ValueError: a value that is not an integer; the message names both variables.
    """
    env = os.environ if environ is None else environ
    size_text, rank_text = env.get("WORLD_SIZE", "1"), env.get("RANK", "0")
    try:
        return parse_int(rank_text, "RANK"), parse_int(size_text, "WORLD_SIZE")
    except ValueError:
        raise ValueError(
            f"WORLD_SIZE={size_text!r} and RANK={rank_text!r} must be integers (torchrun sets them)"
        ) from None


def _run_fit_on_ranks(args: argparse.Namespace) -> int:
    """``eigview fit``, under ``torchrun --nproc-per-node N`` on every rank: the objects are
    split over the ranks (scale/ranks.py), rank 0 reports and writes the model, and each
    rank takes its share of the CPUs unless ``--threads`` says otherwise."""
    from torch_eigview.scale.parallel import available_cpus
    from torch_eigview.scale.ranks import process_group
    from torch_eigview.scale.thread_policy import threads

    rank, size = ranks_from_environment()
    with process_group(rank, size) as rank:
        args.quiet = args.quiet or rank > 0
        share = args.threads if args.threads is not None or size == 1 else max(1, available_cpus() // size)
        with threads(share):
            return run_fit(args)


def _dispatch(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    try:
        runs = {
            "coil": run_coil,
            "fit": run_fit,
            "evaluate": run_evaluate,
            "demo": _run_demo,
        }
        if args.command == "fit":
            return _run_fit_on_ranks(args)
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
    except KeyboardInterrupt as exc:  # Ctrl-C: the writers' message (no previous file lost), no traceback
        said = f": {exc}" if str(exc) else ""
        parser.exit(130, f"eigview: interrupted{said}\n")
    return 1


if __name__ == "__main__":
    sys.exit(main())
