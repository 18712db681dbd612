"""Error types and the validation helpers used at the public boundary.

Public functions validate their inputs here and raise ``ValueError`` for a bad value or
shape and ``TypeError`` for a wrong type; every message names the argument, the
constraint and what was given. Private helpers trust their inputs.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import torch

__all__ = [
    "NotFittedError",
    "as_angle_tensor",
    "check_alpha",
    "check_finite",
    "check_float_tensor",
    "check_ndim",
    "check_number",
]


class NotFittedError(ValueError, AttributeError):
    """Raised when a fitted attribute is used before ``fit`` (as in scikit-learn)."""


def check_float_tensor(x: object, name: str) -> torch.Tensor:
    """Checks that ``x`` is a floating-point tensor and returns it.

    Raises:
        TypeError: ``x`` is not a tensor, or not of a floating dtype.
    """
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if not x.is_floating_point():
        raise TypeError(f"{name} must have a floating dtype, got {x.dtype}")
    return x


def check_ndim(x: torch.Tensor, name: str, ndims: Sequence[int], layout: str) -> None:
    """Checks ``x.ndim`` against the allowed ranks; ``layout`` names them, e.g. "(B, C, H, W)"."""
    if x.ndim not in ndims:
        raise ValueError(f"{name} must have shape {layout}, got shape {tuple(x.shape)}")


def check_finite(x: torch.Tensor, name: str) -> None:
    """Raises ValueError when ``x`` holds NaN or infinite values (never a silent NaN later)."""
    if x.numel() and not bool(torch.isfinite(x).all()):
        n_bad = int((~torch.isfinite(x)).sum())
        raise ValueError(f"{name} must be finite, got {n_bad} NaN or infinite value(s)")


def check_number(value: object, name: str) -> float:
    """A real number (int or float, not bool) as a float; TypeError otherwise."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, got {type(value).__name__} {value!r}")
    return float(value)


def check_alpha(alpha: float, name: str = "alpha") -> float:
    """Checks a seed-view angle in degrees: finite and not a multiple of 180."""
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)):
        raise TypeError(f"{name} must be a number of degrees, got {type(alpha).__name__}")
    alpha = float(alpha)
    if not math.isfinite(alpha):
        raise ValueError(f"{name}={alpha} must be finite")
    if abs(math.sin(math.radians(alpha))) < 1e-8:
        raise ValueError(f"{name}={alpha} must not be a multiple of 180 degrees (sin({name}) is zero)")
    return alpha


def as_angle_tensor(thetas: object, name: str = "thetas", dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """Converts degrees (a number, a sequence or a tensor) to a non-empty finite 1-D tensor."""
    if isinstance(thetas, torch.Tensor):
        if thetas.ndim > 1:
            raise ValueError(f"{name} must be a number or have shape (T,), got shape {tuple(thetas.shape)}")
        if thetas.dtype == torch.bool or thetas.is_complex():
            raise TypeError(f"{name} must hold real angles in degrees, got dtype {thetas.dtype}")
        t = thetas.detach().to(dtype=dtype).reshape(-1)
    elif isinstance(thetas, (int, float)) and not isinstance(thetas, bool):
        t = torch.tensor([float(thetas)], dtype=dtype)
    elif isinstance(thetas, Sequence) and not isinstance(thetas, str):
        if any(isinstance(v, bool) or not isinstance(v, numbers.Real) for v in thetas):
            raise TypeError(f"{name} must hold numbers (degrees), got {thetas!r}")
        t = torch.tensor([float(v) for v in thetas], dtype=dtype)
    else:
        raise TypeError(
            f"{name} must be a number, a sequence of numbers or a tensor, got {type(thetas).__name__}"
        )
    if t.numel() == 0:
        raise ValueError(f"{name} must hold at least one angle, got an empty list")
    check_finite(t, name)
    return t
