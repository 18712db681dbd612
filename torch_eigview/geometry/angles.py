"""Angles in degrees: ranges of gallery and test poses, and wrapping to (−180, 180]."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from torch_eigview.check import VIEW_LIMIT, check_alpha, check_limit

__all__ = ["angle_range", "pair_angles", "seed_angles", "wrap_angle", "wrap_degrees"]


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
    check_limit((stop - start) / step + 1, name, "views per object", *VIEW_LIMIT)
    n = int((stop - start) / step + 1e-9) + 1
    return [start + i * step for i in range(n)]


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
