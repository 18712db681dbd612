"""Image normalizations that a data set applied to its views, applied to synthesized views too.

COIL's "processed" images are size-normalized: each view is cropped to the object's
bounding box and scaled (aspect kept) so that the longer side fills the frame. A view
synthesized by Eq. 2 keeps the geometry of the seed view instead, so before it joins a
gallery of such views it goes through the same normalization (:func:`normalize_extent`).
Both operations are linear in the image for a fixed mask, as Eqs. 3–6 require.
"""

from __future__ import annotations

import torch
from kornia.geometry.transform import remap

from torch_eigview.check import check_float_tensor, check_ndim

__all__ = ["foreground_mask", "normalize_extent"]


def foreground_mask(images: torch.Tensor, threshold: float = 0.05) -> torch.Tensor:
    """Pixels brighter than ``threshold`` (mean over channels): an object on a dark background.

    Args:
        images: (..., C, H, W) images in [0, 1].
        threshold: intensity above which a pixel is foreground.

    Returns:
        (..., H, W) bool mask.
    """
    check_float_tensor(images, "images")
    return images.mean(dim=-3) > threshold


def _first_last(any_along: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Index of the first and last True along the last dim of (P, L); (0, L-1) where none."""
    n = any_along.shape[-1]
    idx = torch.arange(n, device=any_along.device)
    first = torch.where(any_along, idx, n).amin(dim=-1)
    last = torch.where(any_along, idx, -1).amax(dim=-1)
    empty = last < 0
    return torch.where(empty, 0, first), torch.where(empty, n - 1, last)


def normalize_extent(images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """Crops each image to its mask's bounding box and rescales it to fill the frame.

    The scale is the same along x and y (the aspect ratio is kept) and chosen so that the
    box's longer side spans the image, with the box centred; bilinear sampling (kornia
    ``remap``, ``align_corners=True``, zeros outside). An image with an empty mask is
    returned unchanged.

    Args:
        images: (P, C, H, W) images.
        masks: (P, H, W) bool foreground masks.

    Returns:
        (P, C, H, W) normalized images.
    """
    check_float_tensor(images, "images")
    check_ndim(images, "images", (4,), "(P, C, H, W)")
    p, _, h, w = images.shape
    if masks.shape != (p, h, w):
        raise ValueError(f"masks must have shape (P, H, W) = {(p, h, w)}, got {tuple(masks.shape)}")
    if p == 0:
        return images.clone()
    dtype = images.dtype
    y0, y1 = _first_last(masks.any(dim=-1))
    x0, x1 = _first_last(masks.any(dim=-2))
    box_w = (x1 - x0).clamp_min(1).to(dtype)
    box_h = (y1 - y0).clamp_min(1).to(dtype)
    # A side one pixel long has no extent to fill (its scale would be 0): the other side sets it.
    fills = [(n - 1) / box for n, box in ((w, box_w), (h, box_h)) if n > 1] or [torch.ones_like(box_w)]
    scale = (fills[0] if len(fills) == 1 else torch.minimum(*fills)).view(p, 1, 1)
    cx = ((x0 + x1).to(dtype) / 2).view(p, 1, 1)
    cy = ((y0 + y1).to(dtype) / 2).view(p, 1, 1)
    u = torch.arange(w, dtype=dtype, device=images.device).view(1, 1, w)
    v = torch.arange(h, dtype=dtype, device=images.device).view(1, h, 1)
    map_x = (cx + (u - (w - 1) / 2) / scale).expand(p, h, w)
    map_y = (cy + (v - (h - 1) / 2) / scale).expand(p, h, w)
    return remap(images, map_x, map_y, mode="bilinear", padding_mode="zeros", align_corners=True)
