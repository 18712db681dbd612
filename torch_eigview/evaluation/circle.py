"""Where the views of a full-circle COIL experiment lie: seeds, real gallery views, tests.

M seed views evenly spaced over 360° from ``center`` (α = 360°/M), synthesized all round
by :func:`~torch_eigview.synthesis.synthesize_circle`. The baselines are the M seed views
alone (``sparse``) and real views every S degrees (``dense``). The test views are every
available pose that holds no real gallery view.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from torch_eigview.check import check_int
from torch_eigview.geometry.angles import angle_range

__all__ = ["CircleLayout", "circle_layout", "grid_step"]

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
            the poses' step; real views at every available pose (none left to test).

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
    if not tests:
        fewer = (
            f"give fewer seed views ({names[0]} at most {len(grid) // 2})"
            if method != "dense"
            else f"give fewer seed views, or a {names[1]} over {step:g}"
        )
        raise ValueError(
            f"{names[0]}={m} with method {method!r} puts real gallery views at every one of the "
            f"{len(grid)} available poses, leaving none to test: {fewer}"
        )
    return CircleLayout(seed_poses, alpha, real, tests)
