"""The Fig. 2 protocol per camera model (Sec. 4): orthographic, affine and perspective.

The paper's synthetic recognition experiment (Sec. 5.1) on the five rendered objects
(64×64, flow correspondences, synthesized −20°..20° every 1°, 15 components, 450 test views
−45°..44°) with each camera model's synthesis: Eq. 7 (orthographic), the affine solve (an
anisotropic scale, a start angle, the axis off centre) or trifocal transfer (a pinhole
at 4 object radii); see ``synthetic.py``. For each camera: the accuracy per α and number
of seed views N beside the paper's, the ceiling (the same protocol with the rendered
views at the gallery's angles instead of synthesized ones) and the per-pixel error of
views synthesized from seeds 0° and 10° with exact correspondences against the renders,
over the pixels both seeds see (the paper: under 1%).

``--background textured`` renders every view on a coloured, textured backdrop whose
foreground (``--masks given``: the renderer's; ``estimated``: the background model's) is
set apart before synthesis, as a user's photographs are.

Run: ``python examples/paper/camera_models.py [--cameras orthographic affine perspective] [--size 64]``
"""

from __future__ import annotations

import argparse
import math
import statistics

from record import add_record_flag, check_record, command_line, table, write_record
from synthetic import BACKGROUNDS, PAPER_FIG2, run_protocol

from torch_eigview.check import check_alpha
from torch_eigview.datasets import CAMERAS, MASKS, SHAPES
from torch_eigview.scale import threads

#: The largest image side (pixels) the renderer is asked for.
SIZE_LIMIT = 4096


def finite(flag: str):  # type: ignore[no-untyped-def]
    """An argparse type: a finite number, the error naming ``flag``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{flag} must be a finite number, got {text!r}")
        return value

    return parse


def size_arg(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must be an integer, got {text!r}") from None
    if not 2 <= value <= SIZE_LIMIT:
        raise argparse.ArgumentTypeError(f"--size={value} must be >= 2 and <= {SIZE_LIMIT}")
    return value


def parse_args(argv: list[str] | None) -> tuple[argparse.ArgumentParser, argparse.Namespace]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cameras", nargs="+", choices=CAMERAS, default=list(CAMERAS))
    parser.add_argument(
        "--alpha", type=finite("--alpha"), nargs="+", default=[5.0, 10.0, 15.0, 20.0, 30.0], help="degrees"
    )
    parser.add_argument("--views", type=int, nargs="+", choices=(2, 3), default=[2, 3], help="seed views N")
    parser.add_argument("--size", type=size_arg, default=64, help="image side in pixels (>= 2)")
    parser.add_argument("--correspondences", choices=("flow", "exact"), default="flow")
    parser.add_argument("--shapes", default=None, help="comma-separated objects (default: all five)")
    parser.add_argument(
        "--background",
        choices=BACKGROUNDS,
        default="black",
        help="black (the paper's) or a coloured, textured backdrop and ground",
    )
    parser.add_argument(
        "--masks",
        choices=MASKS,
        default="given",
        help="textured: the renderer's masks or ones estimated from the border",
    )
    add_record_flag(parser, "camera_models")
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    shapes = SHAPES if args.shapes is None else tuple(args.shapes.split(","))
    unknown = sorted(set(shapes) - set(SHAPES))
    if unknown:
        parser.error(f"--shapes has unknown shape(s) {unknown}; known: {', '.join(SHAPES)}")
    args.shapes = shapes
    if args.masks != "given" and args.background != "textured":  # black views have no mask to estimate
        parser.error(
            f"--masks {args.masks} goes with --background textured, got --background {args.background}"
        )
    for alpha in args.alpha:
        try:
            check_alpha(alpha, "--alpha")
        except ValueError as exc:
            parser.error(str(exc))
    return parser, args


def main(argv: list[str] | None = None) -> dict[str, dict[str, object]]:
    parser, args = parse_args(argv)
    outs: dict[str, dict[str, object]] = {}
    try:  # a scene too small for the eigenspace: one line naming --size and --shapes
        for camera in args.cameras:
            outs[camera] = run_protocol(
                camera,
                args.alpha,
                args.views,
                size=args.size,
                correspondences=args.correspondences,
                shapes=args.shapes,
                background=args.background,
                masks=args.masks,
            )
    except ValueError as exc:
        parser.error(str(exc))

    def by_run(camera: str, key: str) -> dict[tuple[float, int], float]:
        return {(r["alpha"], r["n_views"]): r["accuracy"] for r in outs[camera][key]}  # type: ignore[attr-defined, misc]

    runs = [(alpha, n) for n in args.views for alpha in args.alpha]
    acc = {camera: by_run(camera, "results") for camera in args.cameras}
    ceiling = {camera: by_run(camera, "ceiling") for camera in args.cameras}
    on = "black background" if args.background == "black" else f"textured background, {args.masks} masks"
    tables = [
        table(
            f"Accuracy (%) of {len(args.shapes)} objects at {args.size}×{args.size}, {args.correspondences} "
            f"correspondences, {on}; N seed views (two at 0° and α, three at −α, 0°, α), the paper's "
            "Fig. 2(ii) beside them.",
            ["α", "N", *args.cameras, "paper"],
            [[a, n, *(acc[c][a, n] for c in args.cameras), PAPER_FIG2.get((a, n))] for a, n in runs],
        ),
        table(
            "The ceiling: the same eigenspace and tests with the rendered views at the gallery's angles "
            "(no synthesis); accuracy (%).",
            ["α", "N", *args.cameras],
            [[a, n, *(ceiling[c][a, n] for c in args.cameras)] for a, n in runs],
        ),
    ]
    thetas = next(iter(outs.values()))["error_thetas"] if outs else []
    rows = []
    for camera in args.cameras:
        errors = outs[camera]["synthesis_error"]
        assert isinstance(errors, dict)
        per_theta = [statistics.fmean(100 * e[i] for e in errors.values()) for i in range(len(thetas))]  # type: ignore[arg-type]
        every = [100 * e for errs in errors.values() for e in errs]
        rows.append([camera, *per_theta, statistics.fmean(every), max(every)])
    tables.append(
        table(
            "Per-pixel mean absolute error (% of the intensity range) of views synthesized from seeds 0° "
            "and 10° with exact correspondences against the renders, over the pixels both seeds see: the "
            "mean over the objects at each θ, the mean and the largest over all.",
            ["camera", *(f"θ = {t:g}°" for t in thetas), "mean", "max"],  # type: ignore[attr-defined]
            rows,
        )
    )
    write_record(
        args.record,
        title="Camera models (Sec. 4, the Fig. 2 protocol)",
        command=command_line(__file__, argv),
        tables=tables,
        results=outs,
    )
    return outs


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
