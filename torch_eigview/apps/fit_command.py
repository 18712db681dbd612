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
from typing import TYPE_CHECKING

from torch_eigview.apps.cli_args import (
    HelpFormatter,
    add_quiet,
    add_threads,
    bounded_int_arg,
    components_arg,
    finite_arg,
    progress_bar,
)
from torch_eigview.apps.coil_command import add_synthesis_arguments, synthesis_options
from torch_eigview.apps.seed_plan import (
    SeedPlan,
    held_out_thetas,
    pick_seeds,
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
    resolve_background,
)
from torch_eigview.files import check_outputs
from torch_eigview.parse import parse_float

if TYPE_CHECKING:
    import torch

    from torch_eigview.datasets.background import BackgroundModel
    from torch_eigview.datasets.manifest import ViewEntry

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
        type=finite_arg("--seeds"),
        nargs="+",
        metavar="DEG",
        help="azimuths of the seed views, degrees: two or more, e.g. 0 10",
    )
    seeds.add_argument(
        "--circle",
        type=bounded_int_arg("--circle", 3),
        metavar="M",
        help="the full circle: M >= 3 seed views 360/M degrees apart from --center, every sector synthesized",
    )
    fit.add_argument(
        "--center", type=finite_arg("--center"), default=0.0, help="with --circle: the first seed's azimuth"
    )
    fit.add_argument(
        "--synth",
        type=finite_arg("--synth"),
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
        type=finite_arg("--reject-poses"),
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


def _read_seeds(
    entries: list[ViewEntry],
    size: tuple[int, int] | None,
    channels: int | None,
    background: BackgroundModel | None = None,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The seed views (V, C, H, W) and, with ``background``, their masks (V, H, W) (else
    None); without ``size`` they must share the first one's size."""
    import torch

    from torch_eigview.datasets.image_views import read_view

    read = [
        read_view(e.path, e.mask, size=size, channels=channels, source=e.source, background=background)
        for e in entries
    ]
    for e, (image, _) in zip(entries, read, strict=True):
        if image.shape != read[0][0].shape:
            raise ValueError(
                f"{e.source}: image {e.path} is (C, H, W)={tuple(image.shape)}, the first seed view "
                f"{entries[0].path} {tuple(read[0][0].shape)}; give --size H W (and --channels) to resize them"
            )
    views = torch.stack([image for image, _ in read])
    return views, None if background is None else torch.stack([mask[0] for _, mask in read])


def _seed_angles(plan: SeedPlan) -> list[float]:
    """The seed views' angles as the estimator takes them: from the first seed's wrapped
    azimuth on, each the signed step from the one before (the gallery's poses are the
    first plus the synthesized offsets)."""
    if plan.thetas is None:
        alpha = 360.0 / len(plan.azimuths)
        return [plan.first + k * alpha for k in range(len(plan.azimuths))]
    angles = [plan.first]
    for step in plan.steps:
        angles.append(angles[-1] + step)
    return angles


def _rule(fields: dict[str, object]) -> str:
    """The background rule as --background spells it."""
    colour = fields["colour"]
    if fields["background"] == "colour" and isinstance(colour, tuple):
        return ",".join(f"{255 * v:g}" for v in colour)
    return str(fields["background"])


def run_fit(args: argparse.Namespace) -> int:
    """Runs ``eigview fit`` on parsed arguments; returns the exit status."""
    from torch_eigview.datasets.background import background_rule
    from torch_eigview.geometry.angles import AROUND_SEEDS
    from torch_eigview.io.checkpoint import save_recognizer
    from torch_eigview.io.images import read_image
    from torch_eigview.io.preprocessing import Preprocessing
    from torch_eigview.method.estimator import FewViewEigenspace
    from torch_eigview.method.memory import MemoryBudgetError
    from torch_eigview.scale.parallel import object_workers
    from torch_eigview.synthesis import Circle

    check_outputs([("--out", args.out)], inputs=manifest_inputs(args))
    background_fields(args)  # a bad --tolerance is named before any file is read
    plan = seed_plan(args.seeds, args.circle, args.center, None if args.synth is None else tuple(args.synth))
    if plan.thetas is None and args.reject_poses is not None:
        raise ValueError(
            f"--reject-poses {' '.join(f'{v:g}' for v in args.reject_poses)} cannot be placed round the full "
            "circle (--circle): its rejection is calibrated on the midpoints between gallery views"
        )
    given = None if args.reject_poses is None else tuple(args.reject_poses)
    held_poses = None if args.reject_rate is None else reject_poses(plan, given)
    held_out_thetas(plan, held_poses)  # names a bad --reject-poses before any image is read
    manifest = load_manifest(args)
    check_not_views([("--out", args.out)], manifest)
    objects = manifest.objects
    picked = {obj: pick_seeds(manifest, obj, plan.azimuths) for obj in objects}  # all checked first
    size = None if args.size is None else (args.size[0], args.size[1])
    first, _ = _read_seeds(picked[objects[0]][:1], size, args.channels)  # the size and channels
    if min(first.shape[2:]) < 2:  # the flow takes image gradients
        entry = picked[objects[0]][0]
        raise ValueError(
            f"{entry.source}: image {entry.path} is (H, W)={tuple(first.shape[2:])}, smaller than 2 x 2: "
            "give --size H W to resize the views"
        )
    size, channels = size or (first.shape[2], first.shape[3]), args.channels or first.shape[1]
    alpha = read_image(picked[objects[0]][0].path, keep_alpha=True).shape[0] in (2, 4)
    why = resolve_background(args, any(e.mask is not None for e in manifest), alpha)
    fields = background_fields(args)
    unit_norm = not args.no_unit_norm
    prep = Preprocessing((int(size[0]), int(size[1])), int(channels), unit_norm=unit_norm, **fields)
    background = background_rule(prep.background, prep.colour, prep.tolerance)
    read = [_read_seeds(picked[obj], size, channels, background) for obj in objects]
    est = FewViewEigenspace(
        args.components,
        synth=Circle(plan.step)
        if plan.thetas is None
        else (AROUND_SEEDS if args.synth is None else tuple(args.synth)),
        options=synthesis_options(args),
        unit_norm=unit_norm,
        reject_rate=args.reject_rate,
        reject_poses=AROUND_SEEDS if given is None else given,
        # One thread per CPU, a few objects each (torch's kernels release the GIL); in order.
        workers=object_workers(0, 0, len(objects), kind="thread"),
        max_views=args.max_views,
    )
    try:
        est.fit(
            [views for views, _ in read],
            _seed_angles(plan),
            labels=objects,
            masks=[masks for _, masks in read],
            progress=progress_bar(args.quiet, "fit objects", "obj"),
        )
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
        "preprocessing": prep.to_json(),
        "seed_azimuths": plan.azimuths,
        "synth": synth_record(args.synth, plan),
        "n_train_views": n_views,
        "reject_rate": args.reject_rate,
        "reject_poses": None if held_poses is None else list(held_poses),
        "manifest": manifest.name,
    }
    save_recognizer(args.out, est.recognizer_, meta)
    k = est.recognizer_.projection.n_components
    rejects = (
        "" if args.reject_rate is None else f", rejection calibrated on {est.n_calibration_views_} views"
    )
    print(
        f"wrote {args.out}: {len(objects)} objects, {n_views} gallery views of (C, H, W)={est.image_shape_}, "
        f"k={k}, seeds at {', '.join(f'{a:g}' for a in plan.azimuths)} degrees{rejects}; "
        f"background {_rule(fields)} ({why})"
    )
    return 0
