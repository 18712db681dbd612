"""The full circle: Sec. 4.1's chain of seed pairs closed on itself.

M seed views evenly spaced over 360° from ``center`` (α = 360°/M); every consecutive pair,
the last seed with the first included, synthesizes its own sector [0, α) from its first
seed, so the gallery goes once round the turntable and every seed's own view comes from
the pair it starts (:func:`torch_eigview.synthesis.pair_of`'s rule). With an ``overlap``
each pair also extrapolates past both of its seeds, so near every seed the gallery holds
the views of both pairs that meet there, each warping that seed by its own correspondence
(COIL-20, every pose tested, 2-degree steps: M = 6 from 89.2 to 92.0 % with 20 degrees,
M = 8 97.2 % with 14 (97.3 without, 1-degree steps), M = 12 99.5 % with 10; each degree adds two
views per pair, so it is off by default and ``--overlap`` opts in). The baselines are the
M seed views alone (``sparse``) and real views every S degrees (``dense``). The test views
are every available pose that holds no real gallery view.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.check import check_int, check_number
from torch_eigview.geometry.angles import angle_range
from torch_eigview.synthesis import PairGeometry, SynthesisOptions, SynthesizedViews, synthesize_views

__all__ = ["CircleLayout", "check_overlap", "circle_layout", "grid_step", "synthesize_circle"]

_TOL = 1e-6


@dataclass(frozen=True)
class CircleLayout:
    """Where the views of a full-circle experiment lie (degrees in [0, 360)).

    Attributes:
        seeds: the M seed poses, from ``center`` on.
        alpha: 360 / M, the angle between consecutive seeds.
        real: the poses of the real gallery views: the seeds (``nvs``, ``sparse``) or
            every dense step (``dense``).
        tests: every available pose that is not in ``real``, sorted.
    """

    seeds: list[float]
    alpha: float
    real: list[float]
    tests: list[float]


def _on_grid(angle: float, poses: Sequence[float]) -> bool:
    return any(min(abs(angle - p), 360 - abs(angle - p)) <= _TOL for p in poses)


def _pose_list(poses: Sequence[float]) -> str:
    shown = [f"{p:g}" for p in poses]
    if len(shown) > 10:
        shown = [*shown[:4], "...", *shown[-2:]]
    return f"[{', '.join(shown)}] ({len(poses)} poses)"


def grid_step(poses: Sequence[float]) -> float:
    """The poses' step: the smallest gap between consecutive ``poses`` round the circle, in
    degrees (5 for COIL's 72 views, 10 for a turntable of 36; 360 for a single pose)."""
    grid = sorted({float(p) % 360 for p in poses})
    return min(b - a for a, b in zip(grid, [*grid[1:], grid[0] + 360], strict=True))


def circle_layout(
    poses: Sequence[float],
    center: float,
    seeds: int,
    method: str,
    dense_step: float | None = None,
    names: tuple[str, str] = ("seeds", "dense_step"),
) -> CircleLayout:
    """The seeds, real gallery views and tests of the full circle over ``poses``.

    Args:
        poses: the available poses in degrees (those of every object).
        center: pose of the first seed view, degrees.
        seeds: M, the number of seed views.
        method: ``"nvs"``, ``"sparse"`` or ``"dense"``.
        dense_step: the dense baseline's step S in degrees, a multiple of the poses'
            step; default the largest such multiple up to 180/M (about 2M real views).
        names: how errors name ``seeds`` and ``dense_step`` (the command passes its flags).

    Raises:
        ValueError: M below 2 or above the number of poses; a seed pose that is not an
            available pose (the message lists them); M = 2 with ``nvs`` (seeds 180° apart,
            where Eq. 7's sin α is zero); a dense step that is not a positive multiple of
            the poses' step.

    Example:
        >>> layout = circle_layout([5.0 * i for i in range(72)], 0.0, 8, "nvs")
        >>> layout.seeds[:3], len(layout.tests)
        ([0.0, 45.0, 90.0], 64)
    """
    grid = sorted({float(p) % 360 for p in poses})
    m = check_int(seeds, names[0], minimum=2, maximum=len(grid))
    if m == 2 and method == "nvs":
        raise ValueError(
            f"{names[0]}=2 puts the seed views 180 degrees apart, where Eq. 7 has sin(alpha) = 0; "
            "synthesis needs 3 or more (sparse and dense take 2)"
        )
    alpha = 360.0 / m
    seed_poses = [(center + k * alpha) % 360 for k in range(m)]
    off = [a for a in seed_poses if not _on_grid(a, grid)]
    if off:
        raise ValueError(
            f"{names[0]}={m} from center={center:g} puts seed views at {[round(a, 3) for a in off]} "
            f"degrees, between the available poses {_pose_list(grid)}"
        )
    real = seed_poses
    if method == "dense":
        pose_step = grid_step(grid)
        # By default about 2M real views: the largest multiple of the poses' step up to 180/M.
        step = (
            max(1, math.floor(180.0 / m / pose_step + _TOL)) * pose_step
            if dense_step is None
            else float(dense_step)
        )
        ratio = step / pose_step
        if not (math.isfinite(ratio) and ratio >= 1 - _TOL and abs(ratio - round(ratio)) <= _TOL):
            raise ValueError(
                f"{names[1]}={step:g} must be a positive multiple of the poses' step {pose_step:g} degrees"
            )
        real = [(center + a) % 360 for a in angle_range(0.0, 360.0 - step / 2, step, names[1])]
        off = [a for a in real if not _on_grid(a, grid)]
        if off:
            raise ValueError(f"{names[1]}={step:g} needs poses {off} missing from {_pose_list(grid)}")
    tests = [p for p in grid if not _on_grid(p, real)]
    return CircleLayout(seed_poses, alpha, real, tests)


def check_overlap(m: int, overlap: object, name: str = "overlap") -> float:
    """``overlap`` as a float, or a ValueError naming ``name``: it must lie in [0, α/2]
    (α = 360/M) and, above 0, keep α + overlap below 90 degrees (Eq. 7 holds within a
    quarter turn of a pair's first seed)."""
    value = check_number(overlap, name)
    alpha = 360.0 / m
    if not (0 <= value <= alpha / 2 and (value == 0 or alpha + value < 90)):
        raise ValueError(
            f"{name}={value:g} must be in [0, alpha/2 = {alpha / 2:g}] degrees and, above 0, below "
            f"90 - alpha = {90 - alpha:g} (M={m}: Eq. 7 holds within a quarter turn of a pair's first seed)"
        )
    return value


def synthesize_circle(
    seeds: torch.Tensor,
    step: float,
    options: SynthesisOptions | None = None,
    masks: torch.Tensor | None = None,
    overlap: float = 0.0,
    geometry: Sequence[PairGeometry] | None = None,
) -> SynthesizedViews:
    """One object's views all round from its M evenly spaced seed views.

    Pair k (seeds k and k + 1 mod M) synthesizes θ = 0, step, … < α = 360/M from seed k;
    with an ``overlap`` it also extrapolates ``overlap`` degrees past each of its seeds
    (θ = −overlap … < 0 and α < θ <= α + overlap, on the grid of ``step``), so near every
    seed the gallery holds the views of both pairs that meet there.

    Args:
        seeds: (M, C, H, W) seed views at 0, α, …, (M − 1)·α from the first, M >= 3.
        step: angle between synthesized views in degrees.
        options: the synthesis options.
        masks: optional (M, H, W) bool seed masks, in place of the brightness threshold.
        overlap: degrees each pair extrapolates past its seeds, in [0, α/2] and below
            90 − α (Eq. 7 holds within a quarter turn of a pair's first seed).
        geometry: the M pairs' correspondences (pair k: seeds k and k + 1 mod M), if
            already computed (:func:`~torch_eigview.synthesis.pair_geometry` of each pair);
            None measures them.

    Returns:
        :class:`~torch_eigview.synthesis.SynthesizedViews`: (M·T, C, H, W) views, their
        angles from the first seed in [0, 360), one elevation per pair, the times and
        each view's pair k.

    Raises:
        ValueError: fewer than 3 seeds, ``overlap`` outside [0, α/2] or not below 90 − α,
            or a ``geometry`` without one record per pair.
    """
    m = seeds.shape[0]
    if m < 3:  # M = 2 puts the seeds 180 degrees apart, where Eq. 7's sin(alpha) is 0
        raise ValueError(f"seeds must hold M >= 3 views evenly spaced round the circle, got M={m}")
    if geometry is not None and len(geometry) != m:
        raise ValueError(f"geometry must hold one record per seed pair (M = {m}), got {len(geometry)}")
    alpha = 360.0 / m
    overlap = check_overlap(m, overlap)
    thetas = [t for t in angle_range(0.0, alpha, step, "circle step") if t < alpha - _TOL]
    n_out = math.floor(overlap / step + _TOL)
    thetas = (
        [-step * i for i in range(n_out, 0, -1)] + thetas + [alpha + step * i for i in range(n_out + 1)][1:]
    )
    views, elevations, seconds = [], [], {"correspondence": 0.0, "synthesis": 0.0}
    for k in range(m):
        pair = [k, (k + 1) % m]
        out = synthesize_views(
            seeds[pair],
            alpha,
            thetas,
            options,
            geometry=None if geometry is None else [geometry[k]],
            masks=None if masks is None else masks[pair],
        )
        views.append(out.views)
        elevations += out.elevations
        for key, value in out.seconds.items():
            seconds[key] += value
    angles = torch.tensor([(k * alpha + t) % 360 for k in range(m) for t in thetas], dtype=torch.float64)
    pairs = torch.arange(m).repeat_interleave(len(thetas))
    return SynthesizedViews(torch.cat(views), angles, elevations, seconds, pairs)
