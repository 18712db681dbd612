"""Image normalizations that a data set applied to its views, applied to synthesized views too.

COIL's "processed" images are size-normalized: each view is cropped to the object's
bounding box and scaled (aspect kept) so that the longer side fills the frame. A view
synthesized by Eq. 2 keeps the geometry of the seed view instead, so before it joins a
gallery of such views it goes through the same normalization (:func:`normalize_extent`).
Both operations are linear in the image for a fixed mask, as Eqs. 3–6 require.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from kornia.geometry.conversions import normalize_pixel_coordinates
from kornia.geometry.transform import remap

from torch_eigview.check import check_float_tensor, check_ndim

__all__ = [
    "FILLED_FRAME",
    "box_fill",
    "foreground_mask",
    "normalize_extent",
    "resolve_extent",
    "seed_foreground",
]

FILLED_FRAME = 0.95
"""A view whose object's bounding box spans at least this fraction of the frame (its
longer side, by :func:`normalize_extent`'s rule) counts as size-normalized. A normalized
data set fills the frame to the pixel (every COIL-20 view: 1.0); a photograph of an
object on a table or a turntable leaves a margin."""


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


def seed_foreground(
    seeds: torch.Tensor, masks: object, threshold: float, *, require_object: bool = False
) -> torch.Tensor:
    """The foreground of each seed view: its mask when given, else :func:`foreground_mask`.

    A mask from a segmentation or a background model decides where a brightness
    threshold could not (an object darker than ``threshold``, a background that is not
    black); without one, the threshold keeps the behaviour of the black-background data.

    Args:
        seeds: (V, C, H, W) seed views.
        masks: None, or (V, H, W) bool masks, True on the object.
        threshold: intensity above which a pixel is foreground when ``masks`` is None.
        require_object: refuse a given mask without an object pixel (the warp would make
            views of nothing, silently).

    Returns:
        (V, H, W) bool.

    Raises:
        TypeError: ``masks`` is not a bool tensor.
        ValueError: ``masks`` does not have shape (V, H, W), or (``require_object``) one
            is all background.
    """
    if masks is None:
        return foreground_mask(seeds, threshold)
    if not isinstance(masks, torch.Tensor) or masks.dtype != torch.bool:
        raise TypeError(f"masks must be None or a bool tensor (True on the object), got {masks!r:.80}")
    want = (seeds.shape[0], *seeds.shape[2:])
    if tuple(masks.shape) != want:
        raise ValueError(
            f"masks must have shape (V, H, W) = {want} to match the seeds, got {tuple(masks.shape)}"
        )
    empty = (~masks.flatten(1).any(1)).nonzero().flatten().tolist() if require_object else []
    if empty:
        raise ValueError(
            f"masks[{empty[0]}] is all background (no True pixel): a seed view must show its object"
        )
    return masks.to(seeds.device)


def _first_last(any_along: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Index of the first and last True along the last dim of (P, L); (0, L-1) where none."""
    n = any_along.shape[-1]
    idx = torch.arange(n, device=any_along.device)
    first = torch.where(any_along, idx, n).amin(dim=-1)
    last = torch.where(any_along, idx, -1).amax(dim=-1)
    empty = last < 0
    return torch.where(empty, 0, first), torch.where(empty, n - 1, last)


def box_fill(masks: torch.Tensor) -> torch.Tensor:
    """How much of the frame each mask's bounding box fills, by :func:`normalize_extent`'s rule.

    Args:
        masks: (P, H, W) bool foreground masks.

    Returns:
        (P,) the larger of the box's width / (W - 1) and height / (H - 1), the side that
        reaches the frame first when the box is scaled; 0 for an empty mask.
    """
    h, w = masks.shape[-2:]
    y0, y1 = _first_last(masks.any(dim=-1))
    x0, x1 = _first_last(masks.any(dim=-2))
    empty = ~masks.flatten(-2).any(dim=-1)
    fill = torch.maximum((x1 - x0) / max(w - 1, 1), (y1 - y0) / max(h - 1, 1))
    return torch.where(empty, 0.0, fill)


def resolve_extent(extent: bool | str, masks: torch.Tensor) -> bool:
    """Whether to size-normalize views synthesized from seeds with foreground ``masks``.

    Args:
        extent: True or False as it is; ``"auto"``: True when every seed view's object
            fills the frame (:data:`FILLED_FRAME`), the mark of a size-normalized data set
            whose synthesized views must be normalized the same way, and False for
            photographs that leave a margin round the object.
        masks: (V, H, W) bool foreground masks of the seed views.

    Returns:
        A bool.
    """
    if extent != "auto" and not isinstance(extent, bool):
        raise ValueError(f"extent must be True, False or 'auto', got {extent!r}")
    if not isinstance(masks, torch.Tensor) or masks.dtype != torch.bool:
        raise TypeError(f"masks must be a bool tensor (True on the object), got {masks!r:.80}")
    if extent != "auto":
        return bool(extent)
    return bool((box_fill(masks) >= FILLED_FRAME).all())


def normalize_extent(images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """Crops each image to its mask's bounding box and rescales it to fill the frame.

    The scale is the same along x and y (the aspect ratio is kept) and chosen so that the
    box's longer side spans the image, with the box centred; bilinear sampling (kornia
    ``remap``'s samples, ``align_corners=True``, zeros outside; the map is separable, so
    float32 and float64 images take :func:`_sample_separable`, the same values bit for bit,
    and other dtypes ``remap`` itself).
    An image with an empty mask is returned unchanged.

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
    map_x = cx + (u - (w - 1) / 2) / scale  # (P, 1, W)
    map_y = cy + (v - (h - 1) / 2) / scale  # (P, H, 1)
    if dtype not in (torch.float32, torch.float64):
        return remap(
            images,
            map_x.expand(p, h, w),
            map_y.expand(p, h, w),
            mode="bilinear",
            padding_mode="zeros",
            align_corners=True,
        )
    return _sample_separable(images, map_x, map_y)


def _sample_separable(images: torch.Tensor, map_x: torch.Tensor, map_y: torch.Tensor) -> torch.Tensor:
    """kornia ``remap`` (bilinear, zeros, ``align_corners=True``) of (P, C, H, W) ``images``
    at a separable map, columns ``map_x`` (P, 1, W) and rows ``map_y`` (P, H, 1): the same
    samples bit for bit.

    ``remap`` stacks its (P, H, W) maps into a (P, H, W, 2) grid and normalizes every
    pixel's pair, about as much work as the sampling itself. A separable map has only
    W + H distinct coordinates: they are normalized by kornia's own
    :func:`~kornia.geometry.conversions.normalize_pixel_coordinates` (``remap``'s
    normalization, so the values are its values), then written into two planes, one per
    coordinate, which ``grid_sample`` reads as (…, 2) pairs through a permuted view."""
    p, _, h, w = images.shape
    # (x, y) pairs as kornia takes them; the other coordinate is a placeholder, not used.
    x = normalize_pixel_coordinates(torch.stack([map_x, torch.zeros_like(map_x)], dim=-1), h, w)[..., 0]
    y = normalize_pixel_coordinates(torch.stack([torch.zeros_like(map_y), map_y], dim=-1), h, w)[..., 1]
    planes = images.new_empty(2, p, h, w)
    planes[0].copy_(x.expand(p, h, w))
    planes[1].copy_(y.expand(p, h, w))
    grid = planes.permute(1, 2, 3, 0)
    return F.grid_sample(images, grid, mode="bilinear", padding_mode="zeros", align_corners=True)
