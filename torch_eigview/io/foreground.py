"""The foreground of a view from its background colours, in numpy: one rule for torch and ONNX.

:class:`~torch_eigview.datasets.background.BackgroundModel` (torch, ``eigview fit`` and
``evaluate``) and the torch-free ``eigview predict --onnx``
(:func:`~torch_eigview.io.preprocessing.prepare_array`) both call :func:`estimate_foreground`,
so an image gives the same mask whichever way it is read. The rule: the background
colours are taken from the image border, where a turntable photograph shows the backdrop
and the table and rarely the object; each is the channel-wise median of the border pixels
still unexplained, with a tolerance from the spread of the border pixels it explains. A
pixel farther than every colour's tolerance is foreground; foreground specks and
background holes smaller than ``min_fraction`` of the image are then flipped (larger holes
stay: a cup's handle shows the backdrop through it).

Medians are the lower middle value (``torch.median``'s rule) and quantiles interpolate
linearly, computed in float64 from float32 distances.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

__all__ = [
    "LUMA",
    "LUMA_WEIGHTS",
    "MASK_BORDER_ERROR",
    "MASK_BORDER_WARNING",
    "Colour",
    "background_colours",
    "check_mask_border",
    "clean_mask",
    "colour_in_channels",
    "estimate_foreground",
]

Colour = tuple[np.ndarray, float]
"""A background colour ``(C,)`` float32 and its tolerance (Euclidean over the channels)."""

# Below this a tolerance would split 8-bit quantization noise (2/255 in three channels).
_MIN_TOLERANCE = 0.02
# The border share that a further background colour must explain; the rest is taken for
# object pixels at the border.
_MIN_COLOUR_SHARE = 0.05


#: ITU-R BT.709 luma, the weights of skimage.color.rgb2gray (RGB to gray wherever views are read).
LUMA_WEIGHTS = (0.2125, 0.7154, 0.0721)
LUMA = np.array(LUMA_WEIGHTS, dtype=np.float32)


# An object seen on a turntable sits inside the frame: a mask that marks most of the image
# border as object is far more likely inverted (zero on the object) than right. Past
# MASK_BORDER_ERROR of the border the mask is refused; past MASK_BORDER_WARNING it is used
# with a warning (an object cut by the frame can reach the border, rarely half of it).
MASK_BORDER_ERROR = 0.9
MASK_BORDER_WARNING = 0.5


def check_mask_border(mask: np.ndarray, what: str) -> None:
    """Refuses (or warns about) an (H, W) mask that marks most of the image border as
    object, naming ``what`` and the share: likely inverted (see :data:`MASK_BORDER_ERROR`)."""
    plane = mask
    if min(plane.shape) < 3:
        return
    ring = np.concatenate([plane[0], plane[-1], plane[1:-1, 0], plane[1:-1, -1]])
    frac = float(ring.mean())
    hint = "is it inverted? non-zero pixels mark the object, zero pixels the background"
    if frac >= MASK_BORDER_ERROR:
        raise ValueError(f"{what} marks {frac:.0%} of the image border as object: {hint}")
    if frac >= MASK_BORDER_WARNING:
        warnings.warn(
            f"{what} marks {frac:.0%} of the image border as object: {hint}", UserWarning, stacklevel=4
        )


def colour_in_channels(colour: Sequence[float], channels: int) -> tuple[float, ...]:
    """A background colour (1 or 3 values) for an image of ``channels``: an RGB colour
    as gray by the BT.709 weights (as an RGB image is converted), a gray one repeated."""
    values = tuple(float(v) for v in colour)
    if len(values) == channels or len(values) not in (1, 3) or channels not in (1, 3):
        return values
    if channels == 1:
        return (min(1.0, float(np.dot(LUMA, np.asarray(values, dtype=np.float32)))),)
    return values * 3


def _lower_median(values: np.ndarray) -> np.ndarray:
    """The lower middle value along axis 0 (for an even count, the smaller of the two)."""
    k = (values.shape[0] - 1) // 2
    return np.partition(values, k, axis=0)[k]


def _distance(pixels: np.ndarray, colour: np.ndarray, axis: int) -> np.ndarray:
    return np.sqrt(np.square(pixels - colour).sum(axis=axis, dtype=np.float32))


def _tolerance(distances: np.ndarray) -> float:
    """Twice the 95th percentile of a colour's own border distances: the backdrop inside
    the frame reaches a little beyond what its border sample shows, and an object pixel is
    nowhere near this close to a backdrop colour unless it has that colour (then the hole
    filling takes it back)."""
    return max(_MIN_TOLERANCE, 2.0 * float(np.quantile(distances.astype(np.float64), 0.95)))


def _own_tolerance(distances: np.ndarray) -> float:
    """The tolerance from the pixels within three median distances of a colour (its own:
    the median colour is the majority's, so the median distance is the majority's spread)."""
    own = distances <= max(3.0 * float(_lower_median(distances)), _MIN_TOLERANCE)
    return _tolerance(distances[own])


def background_colours(
    border: np.ndarray, background: Sequence[float] | None, tolerance: float | None, max_colours: int
) -> list[Colour]:
    """The background colours of one image from its ``(M, C)`` float32 border pixels.

    Args:
        border: ``(M, C)`` the border's pixels.
        background: a given colour (C values) or None to estimate up to ``max_colours``.
        tolerance: a given tolerance or None for each colour's own from the border.
        max_colours: how many colours the border may hold when estimated.
    """
    if background is not None:
        colour = np.asarray(background, dtype=np.float32)
        tol = _own_tolerance(_distance(border, colour, 1)) if tolerance is None else float(tolerance)
        return [(colour, tol)]
    colours: list[Colour] = []
    left = border
    while len(colours) < max_colours and left.shape[0] >= _MIN_COLOUR_SHARE * border.shape[0]:
        colour = _lower_median(left)
        dist = _distance(left, colour, 1)
        tol = _own_tolerance(dist)
        colours.append((colour, tol if tolerance is None else float(tolerance)))
        left = left[dist > tol]
    return colours


def clean_mask(mask: np.ndarray, min_area: int) -> np.ndarray:
    """``(H, W)`` bool ``mask`` with foreground components and background holes smaller
    than ``min_area`` pixels flipped."""
    from scipy import ndimage  # imported here: a quarter second that views without masks never pay

    labels, n = ndimage.label(mask)
    if n:
        sizes = np.bincount(labels.ravel(), minlength=n + 1)
        keep = sizes >= min_area
        keep[0] = False
        mask = keep[labels]
    holes = ~mask & ndimage.binary_fill_holes(mask)
    labels, n = ndimage.label(holes)
    if n:
        sizes = np.bincount(labels.ravel(), minlength=n + 1)
        fill = sizes < min_area
        fill[0] = False
        mask = mask | fill[labels]
    return mask


def estimate_foreground(
    image: np.ndarray,
    background: Sequence[float] | None = None,
    tolerance: float | None = None,
    *,
    border: int = 2,
    max_colours: int = 2,
    min_fraction: float = 0.005,
    where: str = "the image",
) -> np.ndarray:
    """The foreground mask of one image from its background colours.

    Args:
        image: ``(C, H, W)`` float in ``[0, 1]``.
        background: the background colour (C values in ``[0, 1]``), or None to estimate
            the colours from the border.
        tolerance: the largest distance from a background colour that is still
            background, or None for each colour's own from the border's spread.
        border: width in pixels of the border the colours are taken from.
        max_colours: how many background colours the border may hold (estimated colours).
        min_fraction: specks and holes smaller than this fraction of the image are flipped.
        where: how the error names the image.

    Returns:
        ``(H, W)`` bool, True on the object.

    Raises:
        ValueError: the border is too wide for the image, ``background`` has another
            number of channels, or the background leaves no object (the message gives
            the colours and tolerances).

    Example:
        >>> x = np.zeros((3, 8, 8), np.float32)
        >>> x[:, 2:6, 3:6] = 0.8
        >>> int(estimate_foreground(x).sum())
        12
    """
    if not isinstance(image, np.ndarray) or image.ndim != 3:
        got = f"shape {image.shape}" if isinstance(image, np.ndarray) else type(image).__name__
        raise ValueError(f"image must be (C, H, W) as a numpy array, got {got}")
    c, h, w = image.shape
    if image.size and not np.isfinite(image).all():
        raise ValueError(f"image must hold finite values, got NaN or infinite ones in {where}")
    if min(h, w) == 0:
        raise ValueError(f"image has no pixels to tell its foreground from: (H, W)=({h}, {w})")
    if 2 * border >= min(h, w):
        raise ValueError(f"border={border} must be less than half the image side min(H, W)={min(h, w)}")
    if background is not None and len(background) != c:
        raise ValueError(
            f"background={tuple(background)!r} must hold C={c} values, one per channel of the image"
        )
    pixels = np.moveaxis(np.asarray(image, dtype=np.float32), 0, -1)  # (H, W, C)
    ring = np.ones((h, w), dtype=bool)
    ring[border : h - border, border : w - border] = False
    colours = background_colours(pixels[ring], background, tolerance, max_colours)
    near = np.zeros((h, w), dtype=bool)
    for colour, tol in colours:
        near |= _distance(pixels, colour, 2) <= tol
    described = ", ".join(
        f"({', '.join(f'{v:.3g}' for v in col.tolist())}) ± {tol:.3g}" for col, tol in colours
    )
    if background is not None and not near[ring].any():
        # A backdrop surrounds the object: a given colour found nowhere on the border is
        # not the backdrop's, and would remove nothing (or only specks inside the object).
        seen = ", ".join(f"{v:.3g}" for v in _lower_median(pixels[ring]).tolist())
        raise ValueError(
            f"background={described} (given; intensities in [0, 1]) matches no pixel of the border of {where}, "
            f"whose median colour is ({seen}): nothing would be removed; give the backdrop's colour or a "
            "larger tolerance"
        )
    mask = clean_mask(~near, math.ceil(min_fraction * h * w))
    if not mask.any():
        source = "given" if background is not None else "estimated from the border"
        raise ValueError(
            f"background={described} ({source}) leaves no object in {where}: every pixel is within the tolerance "
            "of a background colour (give another background colour or a smaller tolerance)"
        )
    return mask
