"""``eigview fit``: a recognizer from the seed views of any objects listed in a manifest.

Per object, the views at the seed azimuths (``--seeds 0 10 [more]``, or ``--circle M``:
M views 360/M degrees apart from ``--center``) are picked from the manifest, the gallery is
synthesized from them (by default every degree from 20° before the first seed to 20° past
the last; ``--synth`` as ``eigview coil`` takes it: two seeds, that range; more, Sec. 4.1's
sectors, the range extended past the last seed; M: the whole circle), and one
eigenspace and nearest-neighbour gallery are fitted over every object. The model file
(:func:`~torch_eigview.io.checkpoint.save_recognizer`: checksummed, written atomically) records
the preprocessing (:class:`~torch_eigview.io.preprocessing.Preprocessing`), the object
names as label names and the seed azimuths, for ``eigview evaluate`` and ``eigview predict``.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from typing import TYPE_CHECKING

from torch_eigview.apps.cli_args import (
    HelpFormatter,
    add_kernel_arguments,
    add_quiet,
    add_threads,
    angle_arg,
    bounded_int_arg,
    components_arg,
    progress_bar,
)
from torch_eigview.apps.coil_command import add_synthesis_arguments, synthesis_options
from torch_eigview.apps.device_option import add_device_argument, resolve_device
from torch_eigview.apps.seed_plan import (
    held_out_thetas,
    reject_poses,
    seed_plan,
    synth_record,
)
from torch_eigview.apps.view_options import (
    add_background_arguments,
    add_manifest_arguments,
    background_fields,
    check_not_views,
    load_manifest,
    manifest_inputs,
)
from torch_eigview.files import check_outputs
from torch_eigview.parse import parse_float

if TYPE_CHECKING:
    from torch_eigview.io.preprocessing import Preprocessing

__all__ = ["add_fit_command", "run_fit"]


def add_fit_command(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``eigview fit`` and its options to the command's subparsers."""
    fit = sub.add_parser(
        "fit",
        help="fit a recognizer from the seed views of the objects in a manifest",
        description="Per object, its views at the seed azimuths are read from the manifest and the views "
        "between and beyond them synthesized; one eigenspace and nearest-neighbour gallery over every "
        "object are written to --out with the preprocessing its images need.",
        formatter_class=HelpFormatter,
    )
    add_manifest_arguments(fit)
    seeds = fit.add_mutually_exclusive_group(required=True)
    seeds.add_argument(
        "--seeds",
        type=angle_arg("--seeds"),
        nargs="+",
        metavar="DEG",
        help="azimuths of the seed views, degrees: two or more, e.g. 0 10",
    )
    seeds.add_argument(
        "--circle",
        type=bounded_int_arg("--circle", 3),
        metavar="M",
        help="the full circle: M >= 4 seed views 360/M degrees apart from --center, every sector synthesized",
    )
    fit.add_argument(
        "--center",
        type=angle_arg("--center"),
        default=None,
        help="with --circle: the first seed's azimuth (default 0)",
    )
    fit.add_argument(
        "--synth",
        type=angle_arg("--synth"),
        nargs=3,
        default=None,
        metavar=("START", "STOP", "STEP"),
        help="synthesized angles from the first seed for two seeds; each further seed extends the range "
        "by its step; with --circle every STEP degrees round the circle (by default every degree from 20 "
        "before the first seed to 20 past the last, or round the circle; eigview coil's -20 20 1 is the "
        "paper's protocol)",
    )
    fit.add_argument(
        "--size",
        type=bounded_int_arg("--size", 2, "max_image_side"),  # the flow needs 2 x 2
        nargs=2,
        default=None,
        metavar=("H", "W"),
        help="resize every image (and mask) to H x W (default: the seed views' own size)",
    )
    fit.add_argument(
        "--channels",
        type=int,
        choices=(1, 3),
        default=None,
        help="1: gray, 3: RGB (default: the first view's)",
    )
    add_background_arguments(fit, default=None)
    fit.add_argument(
        "-k", "--components", type=components_arg, default=15, help="k, or an energy fraction in (0, 1)"
    )
    add_synthesis_arguments(fit)
    add_kernel_arguments(fit)
    fit.add_argument(
        "--degree",
        type=bounded_int_arg("--degree", 1),
        default=None,
        help="with --kernel poly: its degree (3)",
    )
    fit.add_argument("--no-unit-norm", action="store_true", help="do not L2-normalize views")
    fit.add_argument(
        "--reject-rate",
        type=_rate_arg,
        default=0.05,
        metavar="R",
        help="calibrate the rejection of unknown objects so that a fraction R in (0, 1) of the known "
        "objects' held-out synthesized views is rejected (default 0.05; evaluate/predict --reject use it)",
    )
    fit.add_argument(
        "--no-reject", dest="reject_rate", action="store_const", const=None, help="calibrate no rejection"
    )
    fit.add_argument(
        "--reject-poses",
        type=angle_arg("--reject-poses"),
        nargs=3,
        default=None,
        metavar=("START", "STOP", "STEP"),
        help="angles from the first seed of the held-out views rejection is calibrated on, the gallery's "
        "angles left out: where the known objects will be seen (default: every 2.5 degrees from 45 before "
        "the first seed to 45 past the last; with --circle the midpoints between gallery views all round)",
    )
    fit.add_argument(
        "--max-views",
        type=bounded_int_arg("--max-views", 1),
        default=4096,
        metavar="N",
        help="the most gallery views held in memory at once: a gallery of at most N is fitted at once "
        "(its exact eigenspace), a larger one merged block by block, so that memory does not grow "
        "with the objects",
    )
    add_device_argument(fit, "the synthesis and the eigenspace run")
    fit.add_argument("--out", required=True, metavar="FILE", help="the model file to write")
    add_quiet(fit)
    add_threads(fit)


def _rate_arg(text: str) -> float:
    """``--reject-rate R``: a number in (0, 1) (argparse type)."""
    try:
        value = parse_float(text, "--reject-rate")
    except ValueError:
        value = math.nan
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"--reject-rate must be a number in (0, 1), got {text!r}")
    return value


def _check_kernel_args(args: argparse.Namespace) -> None:
    """--gamma and --degree go with the kernels that use them, before any image is read."""
    kernel = args.kernel
    if args.gamma is not None and kernel not in ("rbf", "poly"):
        raise ValueError(f"--gamma {args.gamma} needs --kernel rbf or poly, got --kernel {kernel}")
    if isinstance(args.gamma, float) and not 0.0 < args.gamma < math.inf:
        raise ValueError(f"--gamma must be a finite number > 0 or 'median', got {args.gamma:g}")
    if args.gamma == "median" and kernel != "rbf":
        raise ValueError(f"--gamma median is a bandwidth for --kernel rbf only, got --kernel {kernel}")
    if args.degree is not None and kernel != "poly":
        raise ValueError(f"--degree {args.degree} needs --kernel poly, got --kernel {kernel}")


def _rule(prep: Preprocessing) -> str:
    """The background rule as --background spells it."""
    if prep.background == "colour" and prep.colour is not None:
        return ",".join(f"{255 * v:g}" for v in prep.colour)
    return prep.background


def run_fit(args: argparse.Namespace) -> int:
    """Runs ``eigview fit`` on parsed arguments; returns the exit status."""
    from torch_eigview.datasets.seed_views import read_seed_views
    from torch_eigview.geometry.angles import AROUND_SEEDS
    from torch_eigview.method.estimator import FewViewEigenspace
    from torch_eigview.method.memory import MemoryBudgetError
    from torch_eigview.scale.parallel import object_workers
    from torch_eigview.scale.ranks import world
    from torch_eigview.synthesis import Circle

    check_outputs([("--out", args.out)], inputs=manifest_inputs(args))
    background_fields(args)  # a bad --tolerance is named before any file is read
    plan = seed_plan(args.seeds, args.circle, args.center, None if args.synth is None else tuple(args.synth))
    if plan.thetas is None and args.reject_poses is not None:
        raise ValueError(
            f"--reject-poses {' '.join(f'{v:g}' for v in args.reject_poses)} cannot be placed round the full "
            "circle (--circle): its rejection is calibrated on the midpoints between gallery views"
        )
    _check_kernel_args(args)
    device = resolve_device(args.device)  # no CUDA: named before any image is read
    given = None if args.reject_poses is None else tuple(args.reject_poses)
    held_poses = None if args.reject_rate is None else reject_poses(plan, given)
    held_out_thetas(plan, held_poses)  # names a bad --reject-poses before any image is read
    manifest = load_manifest(args)
    check_not_views([("--out", args.out)], manifest)
    objects = manifest.objects
    size = None if args.size is None else (args.size[0], args.size[1])
    tolerance = None if args.tolerance is None else args.tolerance / 255.0
    try:  # the reading Python's FewViewEigenspace.fit_manifest does: one path
        seeds = read_seed_views(
            manifest,
            plan.azimuths,
            size=size,
            channels=args.channels,
            background=args.background,
            tolerance=tolerance,
        )
    except ValueError as exc:
        raise ValueError(
            str(exc)
            .replace("give size=(H, W)", "give --size H W")
            .replace("(and channels)", "(and --channels)")
        ) from None
    if device.type != "cpu":  # the estimator works where the seed views are
        seeds = replace(
            seeds,
            views=[v.to(device) for v in seeds.views],
            masks=[None if m is None else m.to(device) for m in seeds.masks],
        )
    prep = seeds.preprocessing
    unit_norm = not args.no_unit_norm
    est = FewViewEigenspace(
        args.components,
        synth=Circle(plan.step)
        if plan.thetas is None
        else (AROUND_SEEDS if args.synth is None else tuple(args.synth)),
        options=synthesis_options(args),
        unit_norm=unit_norm,
        kernel=args.kernel,
        gamma=args.gamma,
        degree=3 if args.degree is None else args.degree,
        reject_rate=args.reject_rate,
        reject_poses=AROUND_SEEDS if given is None else given,
        # One thread per CPU, a few objects each (torch's kernels release the GIL); in order.
        workers=object_workers(0, 0, len(objects), kind="thread"),
        max_views=args.max_views,
    )
    try:
        est.fit_manifest(seeds, progress=progress_bar(args.quiet, "fit objects", "obj"))
    except MemoryBudgetError as exc:  # before any synthesis: say what the command line can change
        raise MemoryBudgetError(
            exc.estimate,
            exc.available,
            exc.bound,
            "give --size H W for smaller images, or a coarser --synth step for fewer views",
        ) from None
    except ValueError as exc:
        text = str(exc)
        for api, flag in (("synth asks", "--synth asks"), ("reject_poses asks", "--reject-poses asks")):
            if text.startswith(api):  # name the flags: the seeds and the range come from them
                raise ValueError(
                    flag
                    + text[len(api) :]
                    .replace(", with seeds at", ", with --seeds at")
                    .replace(
                        f"narrow {api.split()[0]},",
                        f"narrow {flag.split()[0]} (or choose --seeds closer together),",
                    )
                ) from None
        if "exceeds the rank" not in text:
            raise
        # The cause is the -k the command line chose (or its default), not an internal argument.
        if plan.thetas is None:  # every step of each pair's sector [0, alpha)
            per_object = len(plan.azimuths) * math.ceil(360.0 / len(plan.azimuths) / plan.step - 1e-9)
        else:
            per_object = len(plan.thetas)
        raise ValueError(
            f"-k/--components {args.components:g} is more than the {len(objects) * per_object} gallery views "
            f"allow ({exc}): "
            "give a smaller -k, or more views (a smaller --synth step, more objects)"
        ) from exc
    n_views = int(est.gallery_labels_.shape[0])
    meta = {
        "command": "fit",
        "seed_azimuths": plan.azimuths,
        "synth": synth_record(args.synth, plan),
        "n_train_views": n_views,
        "reject_rate": args.reject_rate,
        "reject_poses": None if held_poses is None else list(held_poses),
        "manifest": manifest.name,
    }
    if world()[0] != 0:  # under torchrun every rank holds the same model: rank 0 writes it
        return 0
    est.save(args.out, meta)  # with the preprocessing of the views it read
    k = est.recognizer_.projection.n_components
    rejects = ""
    if args.reject_rate is not None:
        estimate = est.reject_rate_estimate_
        rejects = f", rejection calibrated on {est.n_calibration_views_} views" + (
            "" if estimate is None else f" (estimated {estimate:.1%} of known views rejected)"
        )
    print(
        f"wrote {args.out}: {len(objects)} objects, {n_views} gallery views of (C, H, W)={est.image_shape_}, "
        f"k={k}, seeds at {', '.join(f'{a:g}' for a in plan.azimuths)} degrees{rejects}; "
        f"background {_rule(prep)} ({seeds.reason})"
    )
    return 0
