"""The synthesis with the real motion: what better correspondences alone would change.

Every seed pair's horizontal correspondence is replaced by the motion chained through the
real COIL views between its seeds (``diagnose_flow.chained_disparity``: TV-L1 between
views one pose step apart, composed; both directions; every pixel trusted, so the flow's
occlusion mask is not used); the elevation and the vertical components stay the default
flow's. Everything else is ``eigview coil``'s: the same warp, blend, size normalization,
eigenspace and tests (:func:`run_with_geometry` builds the experiment from the package's
public pieces, with the geometry given). It is a reference, not a strict bound: the chain
adds up TV-L1's small errors and trusts occluded pixels, and where the synthesis with it
does no better than with the flow, the shortfall lies in what the seeds show, not in the
matching. A diagnosis only: it reads the views that the experiment tests on.

The table gives, per center (two seeds α apart, ``eigview coil --alpha A --center C``)
and per M of the full circle (``eigview coil --seeds M``, k = 20, every 5°, pose
interpolated), the accuracy of ``nvs`` with the default flow and with the chained motion
beside the ``dense`` baseline, and the median pose error of the correctly recognized
``nvs`` views.

Run: ``python examples/diagnostics/diagnose_chained.py [--root DIR] [--alpha 10] [--seeds 4 6 8 12]``
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import time
from collections.abc import Callable, Sequence

import torch
from diagnose_flow import chained_disparity
from diagnostic_record import (
    add_centers_flag,
    add_objects_flag,
    add_record_flag,
    add_root_flag,
    check_record,
    coil_folder,
    command_line,
    table,
    text,
    write_record,
)

from torch_eigview import (
    CoilFolder,
    FewViewEigenspace,
    SynthesisOptions,
    synthesize_views,
)
from torch_eigview.evaluation import CoilExperiment, Score, grid_step, score
from torch_eigview.scale import threads
from torch_eigview.synthesis import PairGeometry, pair_geometry, synthesize_circle

Geometry = Callable[..., list[PairGeometry]]


def chained_geometry(
    folder: CoilFolder,
    obj: int,
    poses: Sequence[float],
    options: SynthesisOptions,
    *,
    closed: bool = False,
    step: float = 5.0,
) -> list[PairGeometry]:
    """Each consecutive seed pair's geometry with the chained real motion as its correspondence.

    Args:
        folder: the images.
        obj: the object.
        poses: the seed poses in degrees; each pair is chained the short way round from its
            first seed to its second (decreasing poses for a negative α, through 360° where
            the poses wrap), a whole multiple of ``step`` and less than half a turn.
        options: the synthesis options (the default flow measures the elevation).
        closed: also the pair from the last seed round to the first (the full circle).
        step: the folder's pose step in degrees.

    Returns:
        One :class:`~torch_eigview.synthesis.PairGeometry` per pair; its seconds are the
        flow's and the chain's.

    Raises:
        ValueError: fewer than two poses, or a pair not a nonzero multiple of ``step`` apart.
    """
    if len(poses) < 2:
        raise ValueError(f"poses must hold at least two seed poses, got {list(poses)}")
    ends = list(itertools.pairwise(poses))
    if closed:
        ends.append((poses[-1], poses[0]))
    out = []
    for first, last in ends:
        angle = (last - first + 180.0) % 360.0 - 180.0  # the short way round, in [-180, 180)
        n_steps = round(abs(angle) / step)
        if n_steps < 1 or abs(n_steps * step - abs(angle)) > 1e-6:
            raise ValueError(
                f"seed poses {first:g} and {last:g} must be a nonzero multiple of the pose step {step:g} apart"
            )
        sign = 1.0 if angle > 0 else -1.0
        views = folder.images(obj, [(first + sign * i * step) % 360.0 for i in range(n_steps + 1)])
        flow = pair_geometry(views[[0, -1]], angle, options)[0]
        t0 = time.perf_counter()
        c = flow.correspondence
        d12, d21 = chained_disparity(views), chained_disparity(views.flip(0))
        motion = dataclasses.replace(
            c,
            disparity_12=d12[None].to(c.disparity_12),
            disparity_21=d21[None].to(c.disparity_21),
            valid_12=torch.ones_like(c.valid_12),
            valid_21=torch.ones_like(c.valid_21),
        )
        out.append(PairGeometry(motion, flow.elevation, flow.seconds + time.perf_counter() - t0))
    return out


def _wrap(angles: torch.Tensor) -> torch.Tensor:
    """Angles wrapped to (−180, 180]."""
    return 180 - torch.remainder(180 - angles, 360)


def run_with_geometry(
    exp: CoilExperiment, folder: CoilFolder, geometry: Geometry = chained_geometry
) -> tuple[Score[int], int]:
    """``exp`` (``nvs``, the linear eigenspace, the nearest view's or the interpolated pose)
    run as :meth:`~torch_eigview.evaluation.CoilExperiment.run` runs it, each
    object's seed pairs given ``geometry(folder, obj, poses, options, closed=...)`` instead
    of the flow's; in this process, object after object.

    Returns:
        The :class:`~torch_eigview.evaluation.Score` of the test views and the number of
        gallery views.
    """
    objects = list(exp.objects or folder.objects)
    center = 180.0 - (180.0 - float(exp.center)) % 360.0  # the experiment's center in (-180, 180]
    layout = exp.circle(folder, objects) if exp.seeds is not None else None
    blocks, angles = [], []
    for obj in objects:
        if layout is not None:
            seeds = folder.images(obj, layout.seeds)
            pairs = geometry(folder, obj, layout.seeds, exp.synthesis, closed=True)
            out = synthesize_circle(seeds, exp.synth[2], exp.synthesis, overlap=exp.overlap, geometry=pairs)
        else:
            seed_poses = exp.seed_poses()
            pairs = geometry(folder, obj, seed_poses, exp.synthesis)
            seeds = folder.images(obj, seed_poses)
            out = synthesize_views(seeds, exp.alpha, exp.synth_angles(), exp.synthesis, geometry=pairs)
        blocks.append(out.views)
        angles.append([center + t for t in out.thetas.tolist()])
    # The library's pipeline on the galleries made here (synth=None: the views given are the
    # gallery): one eigenspace of the unit-norm views and the nearest-neighbour recognizer.
    est = FewViewEigenspace(exp.components, synth=None, unit_norm=exp.unit_norm)
    recognizer = est.fit(blocks, angles, labels=objects).recognizer_
    x = blocks[0]
    if layout is not None:
        test_poses = layout.tests
    else:
        step = grid_step([p for obj in objects for p in folder.poses(obj)])
        n = int((exp.test[1] - exp.test[0]) / step + 1e-9) + 1
        test_poses = [center + (exp.test[0] + i * step) for i in range(n)]
    truth = _wrap(torch.tensor(test_poses, dtype=torch.float64)).to(x.dtype)
    tests = ((obj, obj, folder.images(obj, truth.tolist()), truth) for obj in objects)
    return score(recognizer, tests, wrap=True, interpolate_pose=exp.interpolate_pose), sum(
        b.shape[0] for b in blocks
    )


def _row(name: str, base: CoilExperiment, folder: CoilFolder) -> list[object]:
    """One row: ``base`` (nvs) with the flow and with the chained motion, and dense."""
    t0 = time.perf_counter()
    flow = base.run(folder)
    real, _ = run_with_geometry(base, folder)
    dense = dataclasses.replace(base, method="dense").run(folder)
    print(
        f"{name}: {flow.accuracy:.2f} / {real.accuracy:.2f} / {dense.accuracy:.2f} ({time.perf_counter() - t0:.1f} s)"
    )
    return [name, flow.accuracy, real.accuracy, dense.accuracy, flow.pose_median_deg, real.pose_median_deg]


def chained_rows(
    folder: CoilFolder,
    objects: list[int],
    centers: Sequence[float],
    alpha: float,
    ms: Sequence[int],
    k_center: int,
    k_circle: int,
    step: float = 5.0,
) -> list[list[object]]:
    """The table's rows (see the module's docstring): per center at ``alpha`` (k =
    ``k_center``), then per M of the full circle (k = ``k_circle``, synthesized every
    ``step`` degrees, pose interpolated on the manifold)."""
    rows = []
    for c in centers:
        base = CoilExperiment(alpha=alpha, center=c, components=k_center, objects=objects)
        rows.append(_row(f"center {c:g}", base, folder))
    for m in ms:
        base = CoilExperiment(
            seeds=m, components=k_circle, objects=objects, synth=(0.0, 0.0, step), interpolate_pose=True
        )
        rows.append(_row(f"M = {m}", base, folder))
    return rows


def main(argv: list[str] | None = None) -> list[list[object]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_root_flag(parser)
    add_objects_flag(parser)
    add_centers_flag(parser)
    parser.add_argument("--alpha", type=float, default=10.0, help="the per-center seeds' angle, degrees")
    parser.add_argument("--components", type=int, default=15, help="k per center")
    parser.add_argument("--seeds", type=int, nargs="*", default=[4, 6, 8, 12], help="M of the full circle")
    parser.add_argument("--circle-components", type=int, default=20, help="k of the full circle")
    parser.add_argument("--step", type=float, default=5.0, help="the full circle's synthesized step, degrees")
    add_record_flag(parser, "diagnose_chained")
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    folder = coil_folder(parser, args.root)
    objects = list(args.objects or folder.objects)
    try:  # a bad angle or M: one line naming it
        rows = chained_rows(
            folder,
            objects,
            args.centers,
            args.alpha,
            args.seeds,
            args.components,
            args.circle_components,
            args.step,
        )
    except ValueError as exc:
        parser.error(str(exc))
    tab = table(
        f"nvs with the default flow and with the real motion chained through the test views as every seed "
        f"pair's correspondence (a reference), beside dense ({len(objects)} objects); per center α = "
        f"{args.alpha:g}, k = {args.components}; full circle k = {args.circle_components}, every "
        f"{args.step:g}°, pose interpolated. Accuracy (%), median pose error (degrees) of the recognized views.",
        [
            "",
            "nvs (flow)",
            "nvs (chained real motion)",
            "dense",
            "pose median (flow)",
            "pose median (chained)",
        ],
        rows,
    )
    print(text(tab))
    write_record(
        args.record,
        title="Diagnosis: what better correspondences alone would change",
        command=command_line(__file__, argv),
        tables=[tab],
    )
    return rows


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
