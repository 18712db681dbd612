"""Angles in degrees: ranges of gallery and test poses, and wrapping to (−180, 180]."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from torch_eigview.check import VIEW_LIMIT, check_alpha, check_limit

__all__ = [
    "AROUND_SEEDS",
    "REJECT_MARGIN",
    "REJECT_STEP",
    "SEED_MARGIN",
    "angle_range",
    "around_seeds",
    "held_out_range",
    "off_gallery",
    "pair_angles",
    "seed_angles",
    "wrap_angle",
    "wrap_degrees",
]

AROUND_SEEDS = "around-seeds"
"""``synth``'s default in the fitting APIs (``FewViewEigenspace``, the scikit-learn
classifier, ``eigview fit``): every degree from 20° before each object's first seed view
to 20° past its last (:func:`~torch_eigview.geometry.angles.around_seeds`)."""

#: Degrees synthesized past each end seed by default: the paper's 20° (Sec. 5).
SEED_MARGIN = 20.0

#: Degrees past each end seed of the held-out views that calibrate rejection by default,
#: every :data:`REJECT_STEP`: 25° past the gallery on both sides, as the paper's −45°..45°
#: test range lies past its −20°..20° gallery.
REJECT_MARGIN = 45.0

#: The step of those held-out views, degrees.
REJECT_STEP = 2.5


def wrap_angle(angle: float) -> float:
    """One angle in degrees wrapped to (-180, 180], in float64 (:func:`wrap_degrees` for tensors).

    Example:
        >>> wrap_angle(190.0), wrap_angle(-180.0), wrap_angle(365.0)
        (-170.0, 180.0, 5.0)
    """
    return 180.0 - (180.0 - float(angle)) % 360.0


def wrap_degrees(angles: torch.Tensor) -> torch.Tensor:
    """Wraps angles to (-180, 180].

    Example:
        >>> wrap_degrees(torch.tensor([190.0, -180.0, 365.0])).tolist()
        [-170.0, 180.0, 5.0]
    """
    return 180 - torch.remainder(180 - angles, 360)


def angle_range(start: float, stop: float, step: float, name: str) -> list[float]:
    """``start, start + step, …, stop`` (inclusive), validated.

    Raises:
        ValueError: ``step`` is not positive, ``stop < start``, or the range holds more
            angles than the view limit (:data:`~torch_eigview.check.VIEW_LIMIT`, checked
            before the list is made: a tiny step would otherwise fill the memory); the
            message names ``name``.

    Example:
        >>> angle_range(-10.0, 10.0, 5.0, "test")
        [-10.0, -5.0, 0.0, 5.0, 10.0]
    """
    if not (step > 0 and math.isfinite(step)):
        raise ValueError(f"{name} step must be positive, got {step} (a finite number > 0)")
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise ValueError(f"{name} must be finite numbers, got start={start}, stop={stop}, step={step}")
    if stop < start:
        raise ValueError(f"{name} must have start <= stop, got start={start}, stop={stop}")
    check_limit((stop - start) / step + 1, name, "views per object", VIEW_LIMIT)
    n = int((stop - start) / step + 1e-9) + 1
    return [start + i * step for i in range(n)]


def around_seeds(
    steps: Sequence[float], step: float = 1.0, margin: float = SEED_MARGIN
) -> tuple[float, float, float]:
    """``(start, stop, step)`` from ``margin`` degrees before the first seed view to
    ``margin`` past the last, relative to the first, for seeds ``steps`` apart.

    Nothing tells one end seed from the other, so each is extrapolated past by as much.
    The paper's range, −20°..20° from the first seed whatever α (``eigview coil``'s
    protocol), reaches only 20 − α degrees past the second and leaves the second seed out
    altogether once α > 20°.

    Args:
        steps: the signed angles from each seed view to the next, degrees (one or more).
        step: the step of the range, degrees.
        margin: degrees before the first seed and past the last (default
            :data:`SEED_MARGIN`; the fitting APIs place their held-out rejection views
            :data:`REJECT_MARGIN` past them).

    Example:
        >>> around_seeds([10.0]), around_seeds([-30.0]), around_seeds([10.0, 15.0], 5.0)
        ((-20.0, 30.0, 1.0), (-50.0, 20.0, 1.0), (-20.0, 45.0, 5.0))
    """
    seeds = [0.0]
    for s in steps:
        seeds.append(seeds[-1] + float(s))
    return min(seeds) - margin, max(seeds) + margin, float(step)


def held_out_range(steps: Sequence[float]) -> tuple[float, float, float]:
    """The default poses of the held-out views that calibrate rejection, for seeds
    ``steps`` apart: every :data:`REJECT_STEP` degrees from :data:`REJECT_MARGIN` before
    the first seed to as far past the last (:func:`around_seeds`).

    Example:
        >>> held_out_range([10.0])
        (-45.0, 55.0, 2.5)
    """
    return around_seeds(steps, REJECT_STEP, REJECT_MARGIN)


def off_gallery(poses: tuple[float, float, float], gallery: Sequence[float], name: str) -> list[float]:
    """The angles of ``angle_range(*poses)`` that are no gallery angle (1e-6 degrees apart,
    round the circle: 190 is the gallery's −170): where held-out views calibrate rejection.

    Raises:
        ValueError: none is left, or a bad range; the message names ``name``.

    Example:
        >>> off_gallery((-10.0, 10.0, 5.0), [0.0, 365.0], "reject_poses")  # 365 is 5
        [-10.0, -5.0, 10.0]
    """
    held = [t for t in angle_range(*poses, name) if min(abs(wrap_angle(t - g)) for g in gallery) > 1e-6]
    if not held:
        raise ValueError(
            f"{name} {poses} holds gallery angles only: the held-out views must lie off the gallery"
        )
    return held


def pair_angles(alpha: object, n_seeds: int) -> list[float]:
    """Per-pair angles α_n (degrees) of ``n_seeds`` seed views: a number (every pair) or a
    sequence of ``n_seeds − 1`` positive angles (Sec. 4.1's α_n, seed angles increasing)."""
    if isinstance(alpha, torch.Tensor):
        alpha = alpha.detach().reshape(-1).tolist() if alpha.ndim else float(alpha)
    if isinstance(alpha, Sequence) and not isinstance(alpha, str):
        if len(alpha) != n_seeds - 1:
            raise ValueError(
                f"alpha must hold one angle per consecutive seed pair ({n_seeds} views: {n_seeds - 1} angles), "
                f"got {len(alpha)}"
            )
        steps = [check_alpha(a, f"alpha[{n}]") for n, a in enumerate(alpha)]
        bad = [n for n, a in enumerate(steps) if a <= 0]
        if bad:
            raise ValueError(
                f"seed view angles must increase: alpha[{bad[0]}]={steps[bad[0]]} must be positive "
                f"(the angle from seed {bad[0]} to seed {bad[0] + 1}), got alpha={list(alpha)}"
            )
    else:
        steps = [check_alpha(alpha)] * (n_seeds - 1)  # type: ignore[arg-type]
    if abs(sum(steps)) >= 180:
        raise ValueError(f"alpha={alpha} with {n_seeds} seed views spans 180 degrees or more")
    return steps


def seed_angles(steps: list[float]) -> list[float]:
    """Angles of the seed views (degrees) from their per-pair angles α_n: 0, α_1, α_1 + α_2, …."""
    out = [0.0]
    for a in steps:
        out.append(out[-1] + a)
    return out
