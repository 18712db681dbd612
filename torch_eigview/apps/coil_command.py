"""``eigview coil``: the paper's COIL experiment (Fig. 4(b)) and the full circle.

The command's arguments (:func:`add_coil_command`) and its run (:func:`run_coil`): a
folder of ``obj{O}__{P}.png`` images in, a per-object accuracy table out.
"""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from torch_eigview.apps.cli_args import (
    HelpFormatter,
    add_kernel_arguments,
    add_quiet,
    add_threads,
    angle_arg,
    components_arg,
    elevation_arg,
    objects_arg,
    pose_step_arg,
    progress_bar,
    workers_arg,
)
from torch_eigview.apps.view_options import add_background_arguments, background_fields
from torch_eigview.files import check_outputs, write_json

if TYPE_CHECKING:
    import torch

    from torch_eigview.datasets.coil import CoilFolder
    from torch_eigview.evaluation.coil import CoilExperiment, CoilResult
    from torch_eigview.synthesis import SynthesisOptions

__all__ = ["add_coil_command", "add_synthesis_arguments", "format_table", "run_coil", "synthesis_options"]


def add_coil_command(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``eigview coil`` and its options to the command's subparsers."""
    coil = sub.add_parser(
        "coil",
        help="the paper's recognition experiment (Fig. 4(b)) on a folder of COIL-format images",
        description="Seed views of every object in a COIL-format folder (obj{O}__{P}.png), the views "
        "between and beyond them synthesized, one eigenspace over all objects, and every real view over "
        "a test range recognized by its nearest gallery view; prints the per-object accuracy.",
        formatter_class=HelpFormatter,
    )
    coil.add_argument(
        "--folder",
        metavar="DIR",
        default=None,
        help="folder of obj{O}__{P}.png images (COIL-20, COIL-100 or the like); by default coil-20-proc/ "
        "in the data home (TORCH_EIGVIEW_DATA, else ~/torch_eigview_data)",
    )
    coil.add_argument(
        "--alpha",
        type=angle_arg("--alpha"),
        default=None,
        help="angle between seed views, degrees (required without --circle)",
    )
    coil.add_argument(
        "--center",
        type=angle_arg("--center"),
        default=0.0,
        help="pose of the first seed view and centre of the test range, degrees",
    )
    coil.add_argument(
        "--views", type=int, default=2, choices=(2, 3), help="seed views per object, alpha apart"
    )
    coil.add_argument(
        "--circle",
        type=int,
        default=None,
        metavar="M",
        help="the full circle instead of --alpha and --views: M seed views 360/M degrees apart from "
        "--center, every sector synthesized, every other pose tested",
    )
    coil.add_argument(
        "--pose",
        choices=("nearest", "interpolate", "three-view"),
        default="nearest",
        help="the reported pose: the nearest gallery view's, interpolated on the appearance "
        "manifold between it and its neighbours (Murase and Nayar), or that measured again by "
        "geometry against the recognized object's seed views (Eq. 2 over two flows per view)",
    )
    _add_method_arguments(coil)


def _add_method_arguments(coil: argparse.ArgumentParser) -> None:
    """The gallery, synthesis, eigenspace and output options of ``eigview coil``."""
    coil.add_argument(
        "--synth",
        type=angle_arg("--synth"),
        nargs=3,
        default=(-20.0, 20.0, 1.0),
        metavar=("START", "STOP", "STEP"),
        help="synthesized angles from the first seed, degrees, for two seed views; each further seed "
        "extends the range by alpha; with --circle only STEP is used",
    )
    coil.add_argument(
        "--test",
        type=angle_arg("--test"),
        nargs=2,
        default=(-45.0, 45.0),
        metavar=("START", "STOP"),
        help="test poses from --center, degrees: every real view between them (every other pose with --circle)",
    )
    coil.add_argument(
        "-k", "--components", type=components_arg, default=15, help="k, or an energy fraction in (0, 1)"
    )
    coil.add_argument(
        "--method",
        choices=("nvs", "sparse", "dense"),
        default="nvs",
        help="the gallery: nvs, views synthesized from the seeds (the paper's method); the baselines "
        "sparse, the seed views alone, and dense, every real view over the synthesized range",
    )
    coil.add_argument(
        "--objects", type=objects_arg, default=None, help="object ids, e.g. 1-20 or 1,3,5-7; all by default"
    )
    add_synthesis_arguments(coil)
    coil.add_argument(
        "--pose-unit",
        choices=("auto", "index", "degrees"),
        default="auto",
        help="what a file's pose P is: an index (COIL-20: 5*P degrees), degrees (COIL-100), or auto",
    )
    coil.add_argument(
        "--pose-step",
        type=pose_step_arg,
        default=None,
        metavar="DEG",
        help="degrees between pose indices, 5 (COIL-20's) by default: 10 for a turntable of 36 views "
        "named obj1__0.png .. obj1__35.png",
    )
    add_background_arguments(
        coil, auto="auto: the foreground estimated from each image's border colours (backdrop and table)"
    )
    coil.add_argument("--no-unit-norm", action="store_true", help="do not L2-normalize views")
    coil.add_argument("--json", metavar="FILE", help="write the results as JSON")
    coil.add_argument(
        "--save", metavar="FILE", help="write the fitted model (for eigview evaluate, predict and export)"
    )
    add_kernel_arguments(coil)
    coil.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        default="cpu",
        help="where the views, the flow (guided, tvl1, rows; the scikit-image flows stay on the CPU), the warp, "
        "the eigenspace and recognition run",
    )
    coil.add_argument(
        "--workers",
        type=workers_arg,
        default="auto",
        metavar="N",
        help="workers that synthesize the objects (as threads, they also measure --pose three-view), "
        "one object and one torch thread each; auto: one thread per CPU, or with --worker-kind "
        "process one process per CPU when the synthesis is large enough to repay their start-up, "
        "else none",
    )
    coil.add_argument(
        "--worker-kind",
        choices=("auto", "thread", "process"),
        default="auto",
        help="threads of this process (the torch flows and the warp release the GIL) or spawned "
        "processes (for the scikit-image flows, which hold it); auto: processes for "
        "--flow ilk and tvl1-skimage, else threads",
    )
    add_quiet(coil)
    add_threads(coil)


def add_synthesis_arguments(parser: argparse.ArgumentParser) -> None:
    """The novel-view synthesis options (``eigview coil`` and ``eigview fit``): see :func:`synthesis_options`."""
    parser.add_argument(
        "--flow",
        choices=(
            "tvl1",
            "tvl1-skimage",
            "ilk",
            "rows",
            "guided",
        ),  # geometry.flow.METHODS, without importing torch
        default="guided",
        help="correspondences: the row matcher's epipolar matches refined by TV-L1 (guided: seeds far "
        "apart in angle), TV-L1 optical flow in torch (tvl1) or scikit-image's (tvl1-skimage, the "
        "reference), scikit-image's ILK flow, or semi-global matching along rows (rows)",
    )
    parser.add_argument(
        "--elevation",
        type=elevation_arg,
        default="auto",
        help="camera elevation, degrees, or auto: fitted per seed pair from the vertical flow",
    )
    parser.add_argument(
        "--blend",
        choices=("linear", "nearest"),
        default="linear",
        help="pixels both seeds see: cross-dissolve by angle, or the nearer seed alone",
    )
    parser.add_argument(
        "--silhouette",
        action="store_true",
        help="silhouette-aware sampling: only the seeds' foreground enters a synthesized pixel",
    )
    parser.add_argument(
        "--extent",
        choices=("auto", "on", "off"),
        default="auto",
        help="size-normalize synthesized views as a size-normalized data set's (COIL's) are: auto "
        "when every seed view's object fills the frame",
    )


_EXTENT: dict[str, bool | str] = {"auto": "auto", "on": True, "off": False}


def synthesis_options(args: argparse.Namespace) -> SynthesisOptions:
    """The :class:`~torch_eigview.synthesis.SynthesisOptions` of :func:`add_synthesis_arguments`'s flags."""
    from torch_eigview.synthesis import SynthesisOptions

    return SynthesisOptions(
        flow=args.flow,
        elevation=args.elevation,
        extent=_EXTENT[args.extent],
        blend=args.blend,
        silhouette=args.silhouette,
    )


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
    if args.circle is None:
        if args.alpha is None:
            raise ValueError("--alpha is required (the angle between seed views), unless --circle is given")
        return
    if args.circle < 2:
        raise ValueError(f"--circle={args.circle} must be >= 2")
    if args.views != 2:
        raise ValueError(
            f"--circle {args.circle} places its own seed views: it cannot take --views {args.views}"
        )
    if args.alpha is not None and abs(args.alpha - 360.0 / args.circle) > 1e-9:
        raise ValueError(
            f"--alpha {args.alpha:g} contradicts --circle {args.circle} (seeds 360/{args.circle} = "
            f"{360.0 / args.circle:g} degrees apart); leave --alpha out"
        )


def run_coil(args: argparse.Namespace) -> int:
    from torch_eigview.datasets.background import background_rule
    from torch_eigview.datasets.coil import CoilFolder, find_coil_root
    from torch_eigview.evaluation.coil import CoilExperiment
    from torch_eigview.io.checkpoint import save_recognizer

    outputs = [("--json", args.json), ("--save", args.save)]
    check_outputs(outputs, inputs=[("--folder", args.folder)])
    background = background_fields(args)
    folder = CoilFolder(
        find_coil_root(args.folder),
        pose_unit=args.pose_unit,
        pose_step=args.pose_step,
        device=_device(args.device),
        background=background_rule(**background),
    )
    # An output inside the folder must not replace one of the images the run reads.
    check_outputs(
        outputs,
        inputs=[("an image of --folder", folder.path(o, p)) for o in folder.objects for p in folder.poses(o)],
    )
    _check_circle_flags(args)
    experiment = CoilExperiment(
        alpha=args.alpha if args.alpha is not None else 360.0 / args.circle,
        center=args.center,
        views=args.views,
        synth=tuple(args.synth),
        test=tuple(args.test),
        components=args.components,
        method=args.method,
        objects=args.objects,
        unit_norm=not args.no_unit_norm,
        synthesis=synthesis_options(args),
        kernel=args.kernel,
        gamma=args.gamma,
        seeds=args.circle,
        interpolate_pose=args.pose in ("interpolate", "three-view"),
        three_view_pose=args.pose == "three-view",
    )
    experiment.worker_kind = _worker_kind(args)
    experiment.workers = _workers(args, experiment, folder)
    if args.circle is not None:
        experiment.circle(folder, args.objects, names=("--circle", "dense_step"))
    result = experiment.run(folder, progress=progress_bar(args.quiet, f"{args.method} objects", "obj"))
    if args.circle is None:
        title = (
            f"COIL {args.method}: alpha={args.alpha:g}, {experiment.views} seed views, center={args.center:g}"
        )
    else:
        title = f"COIL {args.method}: full circle, {args.circle} seed views from center={args.center:g}"
    if args.kernel:
        title += f", kernel PCA ({args.kernel}, gamma={getattr(result.recognizer.projection, 'gamma', float('nan')):g})"
    print(format_table(result, title))
    if args.json:
        write_json(args.json, result.to_json())
    if args.save:
        meta = {"command": "coil", "alpha": args.alpha, "method": args.method, "accuracy": result.accuracy}
        if background["background"] != "keep":  # predict and evaluate then key the backdrop out the same way
            from torch_eigview.io.preprocessing import Preprocessing

            c, h, w = folder.image_shape
            prep = Preprocessing((h, w), c, unit_norm=not args.no_unit_norm, **background)
            meta["preprocessing"] = prep.to_json()
        save_recognizer(result.recognizer, args.save, meta)
    return 0


def _worker_kind(args: argparse.Namespace) -> str:
    """``--worker-kind``: as given, or for ``auto`` processes for the scikit-image flows (they
    hold Python's GIL, so threads would take turns) and threads for the torch ones."""
    if args.worker_kind != "auto":
        return str(args.worker_kind)
    return "process" if args.flow in ("ilk", "tvl1-skimage") else "thread"


def _workers(args: argparse.Namespace, experiment: CoilExperiment, folder: CoilFolder) -> int:
    """``--workers``: the number given, or for ``auto`` :func:`object_workers`'s choice."""
    from torch_eigview.scale.parallel import object_workers

    if args.workers != "auto":
        return int(args.workers)
    if (experiment.method != "nvs" and not experiment.three_view_pose) or folder.device.type != "cpu":
        return 0  # no synthesis and no geometric pose: nothing to share out
    n_objects = len(folder.objects if args.objects is None else args.objects)  # checked by the run
    per_object = (
        math.ceil(360.0 / experiment.synth[2])  # the full circle, every synth step
        if experiment.seeds is not None
        else len(experiment.synth_angles())
    )
    some = folder.objects[0]  # the folder's images share one size
    pixels = folder.image(some, folder.poses(some)[0])[0].numel()
    return object_workers(per_object * n_objects, pixels, n_objects, kind=experiment.worker_kind)


def _device(name: str) -> torch.device:
    import torch

    if name == "cuda" and not torch.cuda.is_available():
        raise ValueError("--device cuda needs a CUDA device, but torch.cuda.is_available() is False")
    return torch.device(name)
