"""Angles in degrees: ranges of gallery and test poses, and wrapping to (−180, 180]."""

from __future__ import annotations

import math

import torch

from torch_eigview.check import VIEW_LIMIT, check_limit

__all__ = ["angle_range", "wrap_angle", "wrap_degrees"]


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
