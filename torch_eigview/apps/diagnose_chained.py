"""The synthesis with the real motion: what better correspondences alone would change.

Every seed pair's horizontal correspondence is replaced by the motion chained through the
real COIL views between its seeds (:func:`~torch_eigview.apps.diagnose_flow.chained_disparity`,
TV-L1 between views one pose step apart, composed; both directions; every pixel trusted,
so the flow's occlusion mask is not used); the elevation and the vertical components stay
the default flow's. Everything else is ``eigview coil``'s: the same warp, blend, size
normalization, eigenspace and tests. It is a reference, not a strict bound: the chain adds
up TV-L1's small errors and trusts occluded pixels, and where the synthesis with it does
no better than with the flow, the shortfall lies in what the seeds show, not in the
matching. A diagnosis only: it reads the views that the experiment tests on.

``python -m torch_eigview.apps.diagnose chained --root DIR`` prints, per center (two seeds
α apart, ``eigview coil --alpha A --center C``) and per M of the full circle
(``eigview coil --seeds M``), the accuracy of ``nvs`` with the default flow and with the
chained motion beside the ``dense`` baseline, and the median pose error of the correctly
recognized ``nvs`` views.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Iterable, Iterator, Sequence

import torch

from torch_eigview.apps.diagnose_flow import chained_disparity
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.evaluation.circle import CircleLayout
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.synthesis import (
    PairGeometry,
    SynthesisOptions,
    SynthesizedViews,
    pair_geometry,
    synthesize_circle,
    synthesize_views,
)

__all__ = ["ChainedExperiment", "chained_geometry", "chained_table"]


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


@dataclasses.dataclass
class ChainedExperiment(CoilExperiment):
    """:class:`~torch_eigview.evaluation.coil.CoilExperiment` whose ``nvs`` galleries are
    synthesized from :func:`chained_geometry` (in this process, object after object; the
    ``sparse`` and ``dense`` galleries are the experiment's own). Errors and warnings come
    as the synthesis raises them, not named by object as ``eigview coil`` names them."""

    def _synthesized(
        self, folder: CoilFolder, objects: list[int], ticks: Iterable[int], layout: CircleLayout | None
    ) -> Iterator[tuple[int, SynthesizedViews]]:
        for obj in ticks:
            if layout is not None:
                seeds = folder.images(obj, layout.seeds)
                geometry = chained_geometry(folder, obj, layout.seeds, self.synthesis, closed=True)
                yield (
                    obj,
                    synthesize_circle(
                        seeds, self.synth[2], self.synthesis, overlap=self.overlap, geometry=geometry
                    ),
                )
            else:
                poses = self.seed_poses()
                geometry = chained_geometry(folder, obj, poses, self.synthesis)
                seeds = self._seeds(folder, obj)
                yield (
                    obj,
                    synthesize_views(
                        seeds, self.alpha, self.synth_angles(), self.synthesis, geometry=geometry
                    ),
                )


def _row(name: str, base: CoilExperiment, folder: CoilFolder) -> str:
    """One row of the table: ``base`` (nvs) with the flow and with the chained motion, and dense."""
    chained = ChainedExperiment(**{f.name: getattr(base, f.name) for f in dataclasses.fields(base)})
    flow, real, dense = (
        base.run(folder),
        chained.run(folder),
        dataclasses.replace(base, method="dense").run(folder),
    )
    return (
        f"{name:>12} {flow.accuracy:7.2f} {real.accuracy:8.2f} {dense.accuracy:7.2f} "
        f"{flow.pose_median_deg:7.2f} {real.pose_median_deg:8.2f}"
    )


def chained_table(
    folder: CoilFolder,
    objects: list[int],
    centers: Sequence[float],
    alpha: float,
    ms: Sequence[int],
    k_center: int,
    k_circle: int,
    step: float = 5.0,
) -> str:
    """The table of the module's docstring: per center at ``alpha`` (k = ``k_center``), then
    per M of the full circle (k = ``k_circle``, synthesized every ``step`` degrees, pose
    interpolated on the manifold)."""
    lines = [
        "nvs with the default flow and with the real motion chained through the test views (a reference)",
        f"{'':>12} {'flow':>7} {'chained':>8} {'dense':>7} {'pose md':>7} {'chained':>8}",
    ]
    for c in centers:
        base = CoilExperiment(alpha=alpha, center=c, components=k_center, objects=objects)
        lines.append(_row(f"center {c:g}", base, folder))
    for m in ms:
        base = CoilExperiment(
            seeds=m, components=k_circle, objects=objects, synth=(0.0, 0.0, step), interpolate_pose=True
        )
        lines.append(_row(f"M = {m}", base, folder))
    return "\n".join(lines)
