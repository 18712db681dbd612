"""A torch Dataset over a :class:`~torch_eigview.datasets.manifest.ViewManifest`: images, masks and angles.

Pixels are read with :func:`~torch_eigview.io.images.read_image` and converted with
:func:`~torch_eigview.io.images.to_unit_float`, as :class:`~torch_eigview.datasets.coil.CoilFolder`
and ``eigview predict`` do, so a COIL view is the same tensor whichever way it is read.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils.data import Dataset

from torch_eigview.check import SIDE_LIMIT, check_int, check_limit
from torch_eigview.datasets.background import BackgroundModel
from torch_eigview.datasets.manifest import ViewManifest
from torch_eigview.io.foreground import LUMA_WEIGHTS, check_mask_border, colour_in_channels
from torch_eigview.io.images import image_size, read_image, to_unit_float

__all__ = [
    "ASPECT_TOLERANCE",
    "ViewDataset",
    "read_view",
    "warn_aspect_changes",
]


# Resizing views whose aspect ratios differ by more than this (relative) squeezes some
# objects and not others; a camera's own ratio, shared by all views, is harmless.
ASPECT_TOLERANCE = 0.02


def warn_aspect_changes(
    paths: Sequence[str | os.PathLike[str]], sources: Sequence[str] | None = None
) -> None:
    """Warns, naming the file and both sizes, for each image whose aspect ratio (H/W, read
    from its header) differs from the first image's by more than :data:`ASPECT_TOLERANCE`:
    resized to one size, such a view would be squeezed where the others are not.

    Example:
        >>> warn_aspect_changes([])  # nothing to compare
    """
    sizes = [image_size(p) for p in paths]
    if not sizes or sizes[0] is None:
        return
    h0, w0 = sizes[0]
    for i, hw in enumerate(sizes[1:], start=1):
        if hw is None or min(hw) == 0 or min(h0, w0) == 0:
            continue
        if abs(math.log((hw[0] / hw[1]) / (h0 / w0))) > math.log1p(ASPECT_TOLERANCE):
            where = f"{sources[i]}: " if sources is not None else ""
            warnings.warn(
                f"{where}image {os.fspath(paths[i])} is {hw[0]} x {hw[1]} (H x W), another aspect ratio than "
                f"the first image {os.fspath(paths[0])} ({h0} x {w0}): resized to one size it is squeezed",
                UserWarning,
                stacklevel=2,
            )


def _check_size(size: object) -> tuple[int, int] | None:
    if size is None:
        return None
    if not isinstance(size, Sequence) or isinstance(size, str) or len(size) != 2:
        raise TypeError(f"size must be None or a pair (H, W) of ints, got {size!r}")
    hw = check_int(size[0], "size[0] (H)", minimum=1), check_int(size[1], "size[1] (W)", minimum=1)
    check_limit(max(hw), "size", "pixels per image side", SIDE_LIMIT)  # a view is H x W floats in memory
    return hw


def _check_channels(channels: object) -> int | None:
    if channels is not None and check_int(channels, "channels") not in (1, 3):
        raise ValueError(f"channels must be 1, 3 or None, got {channels}")
    return channels  # type: ignore[return-value]


def _resize(
    image: torch.Tensor, mask: torch.Tensor, size: tuple[int, int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """Resamples ``image`` ``(C, H, W)`` and ``mask`` ``(1, H, W)`` bool to ``size``.

    The image is resampled antialiased-bilinear (each output pixel averages over its
    footprint when shrinking, so no detail aliases). The mask is area-averaged into the
    fraction of object under each output pixel (a nearest-neighbour copy when enlarging)
    and thresholded at one half, which keeps its area unbiased where nearest-neighbour
    sampling would drop or keep thin parts at random.
    """
    if tuple(image.shape[-2:]) == size:
        return image, mask
    work = image.double() if image.dtype == torch.float64 else image.float()
    out = F.interpolate(work[None], size=size, mode="bilinear", antialias=True, align_corners=False)[0]
    frac = F.interpolate(mask[None].float(), size=size, mode="bilinear", antialias=True, align_corners=False)[
        0
    ]
    return out.clamp(0.0, 1.0).to(image.dtype), frac >= 0.5


class ViewDataset(Dataset[dict[str, Any]]):
    """The views of a manifest as dicts of tensors, read lazily (fit for a ``DataLoader``).

    Each item holds ``image`` ``(C, H, W)`` of ``dtype`` in ``[0, 1]``, ``mask``
    ``(1, H, W)`` bool (True on the object), ``object`` (str), ``azimuth`` (float, degrees
    in ``[0, 360)``) and ``elevation`` (float, degrees, ``nan`` when not given). The mask
    is the manifest's mask image (non-zero is object), else the image's alpha channel
    (non-zero is object), else all True. Gray images give ``C = 1``, RGB ``C = 3``
    unless ``channels`` converts them.

    Args:
        manifest: The views.
        size: ``(H, W)`` every image and mask is resized to, or None to keep each file's
            size (then a ``DataLoader`` batch needs files of one size); each side at most
            the ``max_image_side`` limit (512 by default, :mod:`torch_eigview.config`).
        channels: ``1`` (RGB to gray with the BT.709 weights), ``3`` (gray repeated) or
            None to keep each file's channels.
        dtype: Floating dtype of the images.
        background: None to give the images as read, or a
            :class:`~torch_eigview.datasets.background.BackgroundModel`: then a view
            without a mask (image or alpha) gets the model's estimated mask, and every
            image's background is set to the model's ``fill`` (kept when None), after
            resizing and before the channels are converted (the mask is found in the
            file's own colours; a given background colour of 1 or 3 values is converted
            to the file's channels).

    Raises:
        TypeError: A wrong type of argument.
        ValueError: ``size`` or ``channels`` is out of range. Reading an item raises
            ValueError naming the manifest line and the file when the image or mask cannot
            be read, the mask's size differs from the image's, or (with ``background``) a
            mask is all background or the background colour leaves no object.
    """

    def __init__(
        self,
        manifest: ViewManifest,
        size: Sequence[int] | None = None,
        *,
        channels: int | None = None,
        dtype: torch.dtype = torch.float32,
        background: BackgroundModel | None = None,
    ) -> None:
        if not isinstance(manifest, ViewManifest):
            raise TypeError(f"manifest must be a ViewManifest, got {type(manifest).__name__}")
        if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
            raise TypeError(f"dtype must be a floating torch.dtype, got {dtype!r}")
        _check_channels(channels)
        if background is not None and not isinstance(background, BackgroundModel):
            raise TypeError(f"background must be a BackgroundModel or None, got {type(background).__name__}")
        self.background = background
        self.manifest = manifest
        self.size = _check_size(size)
        self.channels = channels
        self.dtype = dtype

    def __len__(self) -> int:
        return len(self.manifest)

    def __repr__(self) -> str:
        return (
            f"ViewDataset({self.manifest!r}, size={self.size}, channels={self.channels}, dtype={self.dtype}, "
            f"background={self.background!r})"
        )

    def __getitem__(self, index: int) -> dict[str, Any]:
        if not -len(self) <= index < len(self):  # IndexError: the end of iteration for a Dataset
            raise IndexError(f"index={index} is out of range for {len(self)} views")
        entry = self.manifest[index]
        image, mask = read_view(
            entry.path,
            entry.mask,
            size=self.size,
            channels=self.channels,
            dtype=self.dtype,
            source=entry.source,
            background=self.background,
        )
        return {
            "image": image,
            "mask": mask,
            "object": entry.object,
            "azimuth": float(entry.azimuth),
            "elevation": float(entry.elevation),
        }


def read_view(
    path: str | os.PathLike[str],
    mask: str | os.PathLike[str] | None = None,
    *,
    size: Sequence[int] | None = None,
    channels: int | None = None,
    dtype: torch.dtype = torch.float32,
    source: str | None = None,
    background: BackgroundModel | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """One image file and its mask as :class:`ViewDataset` gives them (``eigview predict`` reads so too).

    Args:
        path: The image file.
        mask: Its mask image (non-zero is object), or None (the alpha channel, else all True).
        size, channels, dtype: As :class:`ViewDataset`'s.
        source: Where the file was listed (a manifest line), prefixed to errors (the
            messages name the files in any case).
        background: As :class:`ViewDataset`'s: None gives the image as read; a
            :class:`~torch_eigview.datasets.background.BackgroundModel` estimates the mask
            of a view without one and sets the background to its ``fill``, after resizing.

    Returns:
        ``(image, mask)``: ``(C, H, W)`` of ``dtype`` in ``[0, 1]`` and ``(1, H, W)`` bool.

    Raises:
        ValueError: The image or mask cannot be read, the mask's size differs from the
            image's, or (with ``background``) the mask is all background or the background
            colour leaves no object; the message names ``source`` and the files.
    """
    hw = _check_size(size)
    _check_channels(channels)
    try:
        arr = read_image(path, keep_alpha=True)
        alpha = arr[-1:] if arr.shape[0] in (2, 4) else None
        colour = arr[:-1] if alpha is not None else arr
        if alpha is not None and mask is None and bool((alpha > 0).all()):
            alpha = None  # an opaque alpha channel marks no background: no mask
        if mask is not None:
            found = np.asarray(read_image(mask, what="mask").any(axis=0, keepdims=True))
            if found.shape[1:] != colour.shape[1:]:
                raise ValueError(
                    f"mask {mask} has size (H, W)={found.shape[1:]}, its image {path} "
                    f"{colour.shape[1:]}: they must match"
                )
            check_mask_border(found[0], f"mask {mask}")
        elif alpha is not None:
            found = np.asarray(alpha > 0)
            check_mask_border(found[0], f"the alpha channel of {path}")
        else:
            found = np.ones((1, *colour.shape[1:]), dtype=bool)
    except ValueError as exc:
        if source is None:
            raise
        raise ValueError(f"{source}: {exc}") from None
    work = np.float64 if dtype == torch.float64 else np.float32
    image = torch.from_numpy(to_unit_float(colour, work)).to(dtype)
    out = torch.from_numpy(np.ascontiguousarray(found))
    if background is None:
        image = _convert(image, channels)
        return _resize(image, out, hw) if hw is not None else (image, out)
    # The foreground is found in the file's own channels (a colour photograph's backdrop
    # is told apart by its colour, not only its gray), then the channels are converted.
    if hw is not None:
        image, out = _resize(image, out, hw)
    if background.background is not None:
        background = replace(background, background=colour_in_channels(background.background, image.shape[0]))
    given = mask is not None or alpha is not None
    try:
        masked, fg = background.apply(image[None], out[None] if given else None)
    except ValueError as exc:
        where = f"{source}: {path}" if source is not None else str(path)
        raise ValueError(f"{where}: {exc}") from None
    return _convert(masked[0], channels), fg[0]


def _convert(image: torch.Tensor, channels: int | None) -> torch.Tensor:
    """``image`` (C, H, W) with ``channels``: gray repeated, or RGB to gray (BT.709)."""
    if channels == 3 and image.shape[0] == 1:
        return image.expand(3, -1, -1).clone()
    if channels == 1 and image.shape[0] == 3:
        weights = torch.tensor(LUMA_WEIGHTS, dtype=image.dtype).view(3, 1, 1)
        return (image * weights).sum(0, keepdim=True).clamp(0.0, 1.0)
    return image
