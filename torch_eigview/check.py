"""Validation helpers used at the public boundary.

Public functions validate their inputs here and raise ``ValueError`` for a bad value or
shape and ``TypeError`` for a wrong type; every message names the argument, the
constraint and what was given. Private helpers trust their inputs.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import torch

from torch_eigview.config import check_limit

__all__ = [
    "as_angle_tensor",
    "check_alpha",
    "check_choice",
    "check_finite",
    "check_float_tensor",
    "check_image_shape",
    "check_int",
    "check_kernel_params",
    "check_limit",
    "check_magnitude",
    "check_n_components",
    "check_ndim",
    "check_number",
    "check_positive",
    "check_view_input",
    "check_view_pair",
]


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


def check_view_pair(view1: object, view2: object) -> tuple[torch.Tensor, torch.Tensor]:
    """Two views of one pair: float tensors (C, H, W) or (B, C, H, W) of one shape, finite;
    returned batched, (B, C, H, W) each."""
    v1 = check_float_tensor(view1, "view1")
    v2 = check_float_tensor(view2, "view2")
    check_ndim(v1, "view1", (3, 4), "(C, H, W) or (B, C, H, W)")
    if v2.shape != v1.shape:
        raise ValueError(f"view2 must have the shape of view1 {tuple(v1.shape)}, got {tuple(v2.shape)}")
    check_finite(v1, "view1")
    check_finite(v2, "view2")
    return (v1[None], v2[None]) if v1.ndim == 3 else (v1, v2)


def check_number(value: object, name: str) -> float:
    """A real number (int or float, not bool) as a float; TypeError otherwise."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, got {type(value).__name__} {value!r}")
    return float(value)


def check_alpha(alpha: float, name: str = "alpha") -> float:
    """Checks a seed-view angle in degrees: finite, within [-360, 360] and not a multiple of 180."""
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)):
        raise TypeError(f"{name} must be a number of degrees, got {type(alpha).__name__}")
    alpha = float(alpha)
    if not math.isfinite(alpha):
        raise ValueError(f"{name}={alpha} must be finite")
    if abs(alpha) > 360:
        # Beyond a turn the angle is another angle in disguise, and at 1e300 degrees a
        # float's spacing exceeds the turn: sin(alpha) would be noise.
        raise ValueError(f"{name}={alpha} must be an angle between seed views in [-360, 360] degrees")
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


def check_int(value: object, name: str, minimum: int | None = None, maximum: int | None = None) -> int:
    """An integer (a Python or NumPy integer, not bool) within ``[minimum, maximum]``, as an int.

    Raises:
        TypeError: ``value`` is not an integer.
        ValueError: ``value`` lies outside the bounds; the message gives the bound.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise ValueError(f"{name}={value} must be >= {minimum}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name}={value} must be <= {maximum}")
    return value


def check_n_components(n_components: object) -> int | float:
    """An int >= 1 (a number of components) or a float in (0, 1) (an energy fraction)."""
    if isinstance(n_components, bool) or not isinstance(n_components, numbers.Real):
        raise TypeError(
            "n_components must be an int >= 1 or a float in (0, 1) (energy fraction), "
            f"got {type(n_components).__name__} {n_components!r}"
        )
    if isinstance(n_components, numbers.Integral):
        if n_components < 1:
            raise ValueError(f"n_components={n_components} must be >= 1 when an int")
        return int(n_components)
    fraction = float(n_components)
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"n_components={fraction} must be in (0, 1) when a float (an energy fraction)")
    return fraction


def check_image_shape(image_shape: object, n_features: int, name: str) -> tuple[int, int, int] | None:
    """Validates an optional ``(C, H, W)`` whose product must be ``n_features``."""
    if image_shape is None:
        return None
    if not isinstance(image_shape, (tuple, list, torch.Size)) or len(image_shape) != 3:
        raise TypeError(f"{name} must be None or a (C, H, W) tuple of 3 ints, got {image_shape!r}")
    if any(isinstance(v, bool) or not isinstance(v, int) for v in image_shape):
        raise TypeError(f"{name} must hold ints, got {image_shape!r}")
    shape = (int(image_shape[0]), int(image_shape[1]), int(image_shape[2]))
    if min(shape) < 1 or math.prod(shape) != n_features:
        raise ValueError(
            f"{name}={shape} must be positive with C*H*W equal to the {n_features} features, "
            f"got C*H*W={math.prod(shape)}"
        )
    return shape


def check_view_input(
    x: object, in_features: int, image_shape: tuple[int, int, int] | None, dtype: torch.dtype
) -> None:
    """Checks a batch of views for a frozen layer: (B, N) or (B, C, H, W), floating.

    Any floating dtype passes: the layer casts its input to ``dtype`` (its buffers'), so
    autocast's bfloat16 or float16 activations and float64 inputs feed a float32 layer as
    they are. Integer images (uint8 pixels in [0, 255]) are refused: the eigenspace was
    fitted on views in [0, 1], so a silent cast would project values 255 times too large.

    Static checks only (ndim, trailing sizes, dtype): torch.export and torch.compile evaluate
    them once and never on data. torch.jit.trace cannot record Python checks (its sizes are
    tensors, so they would only emit TracerWarnings): they are skipped there.
    """
    if torch.jit.is_tracing():
        return
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"x must be a torch.Tensor, got {type(x).__name__}")
    if image_shape is None:
        layout = f"(B, {in_features}) or (B, C, H, W) with C*H*W = {in_features}"
    else:
        layout = f"(B, {in_features}) or (B, {', '.join(map(str, image_shape))})"
    trailing = tuple(x.shape[1:])
    if x.ndim == 4 and image_shape is not None:
        ok = trailing == image_shape
    else:
        ok = x.ndim in (2, 4) and math.prod(trailing) == in_features
    if not ok:
        raise ValueError(f"x must have shape {layout}, got shape {tuple(x.shape)}")
    if not x.dtype.is_floating_point:
        raise TypeError(
            f"x must have a floating dtype (the layer casts it to its buffers' {dtype}), got {x.dtype}; "
            "scale integer images to [0, 1] floats first (e.g. x.float() / 255)"
        )


def check_choice(value: object, name: str, choices: Sequence[str]) -> str:
    """A string among ``choices``; TypeError or ValueError otherwise."""
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a str, one of {tuple(choices)}, got {type(value).__name__}")
    if value not in choices:
        raise ValueError(f"{name}={value!r} must be one of {tuple(choices)}")
    return value


def check_kernel_params(gamma: object, degree: object, coef0: object) -> tuple[float | None, int, float]:
    """Validates γ (None or > 0), the degree (int >= 1) and coef0 (finite)."""
    if gamma is not None:
        if isinstance(gamma, bool) or not isinstance(gamma, (int, float)):
            raise TypeError(f"gamma must be None or a positive number, got {type(gamma).__name__} {gamma!r}")
        if not (math.isfinite(gamma) and gamma > 0):
            raise ValueError(f"gamma={gamma} must be a finite number > 0")
        gamma = float(gamma)
    if isinstance(degree, bool) or not isinstance(degree, int):
        raise TypeError(f"degree must be an int >= 1, got {type(degree).__name__} {degree!r}")
    if degree < 1:
        raise ValueError(f"degree={degree} must be >= 1")
    if isinstance(coef0, bool) or not isinstance(coef0, (int, float)):
        raise TypeError(f"coef0 must be a number, got {type(coef0).__name__} {coef0!r}")
    if not math.isfinite(coef0):
        raise ValueError(f"coef0={coef0} must be finite")
    return gamma, degree, float(coef0)


def check_positive(value: object, name: str, *, allow_zero: bool = False) -> float:
    """A finite real number > 0 (>= 0 with ``allow_zero``) as a float; NaN is refused."""
    number = check_number(value, name)
    if not math.isfinite(number) or number < 0 or (number == 0 and not allow_zero):
        sign, bound = ("non-negative", ">= 0") if allow_zero else ("positive", "> 0")
        raise ValueError(f"{name}={value!r} must be {sign} (a finite number {bound})")
    return number


#: The limit on views per object, and on an image's side (:mod:`torch_eigview.config`).
VIEW_LIMIT = "max_views"
SIDE_LIMIT = "max_image_side"


def check_magnitude(x: torch.Tensor, name: str, n_terms: int) -> None:
    """Checks that products of ``x``'s values, summed ``n_terms`` at a time (a Gram or scatter
    entry), neither overflow nor underflow ``x``'s dtype; also that ``x`` is finite.

    An overflow or underflow would otherwise surface later as a false cause ("all views are
    identical", a failed eigensolver); the message names the largest magnitude and the range.
    The largest magnitude is one min/max reduction, without a temporary copy of ``x``.

    Raises:
        ValueError: NaN or infinite values, or a magnitude outside the dtype's usable range.
    """
    if x.numel() == 0:
        return
    smallest, biggest = torch.aminmax(x)  # NaN propagates; ~20x faster than an inf-norm on CPU
    largest = max(-float(smallest), float(biggest))
    if not math.isfinite(largest):
        check_finite(x, name)  # names the NaN or infinite values
    if largest == 0:
        return
    info = torch.finfo(x.dtype)
    # Centred values reach 2·max|x|; a sum of n_terms products must stay below the max.
    high = math.sqrt(info.max / (4.0 * max(n_terms, 1)))
    # The rank tolerance is ~eps·max² (decomposition.linalg.rank_tolerance); below
    # sqrt(tiny / eps) that scale is subnormal and the small eigenvalues lose their bits.
    low = math.sqrt(info.tiny / info.eps)
    if largest > high:
        raise ValueError(
            f"{name} is too large for {x.dtype}: its largest magnitude {largest:.3g} exceeds {high:.3g}, "
            f"so products of its values overflow; rescale it (e.g. to [0, 1]) or use float64"
        )
    if largest < low:
        raise ValueError(
            f"{name} is too small for {x.dtype}: its largest magnitude {largest:.3g} is below {low:.3g}, "
            f"so products of its values underflow; rescale it (e.g. to [0, 1]) or use float64"
        )
