"""Tests for ``normalize_extent`` and ``foreground_mask``: geometry, identity cases, linearity."""

from __future__ import annotations

import pytest
import torch
from kornia.geometry.transform import remap

from torch_eigview.warp.normalize import (
    FILLED_FRAME,
    box_fill,
    foreground_mask,
    normalize_extent,
    resolve_extent,
)

TOL = {torch.float32: dict(atol=1e-5, rtol=1e-5), torch.float64: dict(atol=1e-10, rtol=1e-10)}
# kornia's remap goes through normalized coordinates: an identity or integer-aligned map is
# exact up to rounding of those coordinates, about eps * W in the value for unit images.
IDENTITY_ATOL = {torch.float32: 1e-5, torch.float64: 1e-10}
DTYPES = pytest.mark.parametrize("dtype", [torch.float32, torch.float64], ids=["float32", "float64"])


def rand(*shape: int, seed: int, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.rand(*shape, generator=gen, dtype=torch.float64).to(dtype)


def box(mask: torch.Tensor) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1), inclusive, of the True pixels of an (H, W) mask."""
    rows = mask.any(dim=1).nonzero().flatten()
    cols = mask.any(dim=0).nonzero().flatten()
    return int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])


def rectangle(h: int, w: int, y0: int, y1: int, x0: int, x1: int, dtype: torch.dtype) -> torch.Tensor:
    """(1, 1, H, W) image: ones on rows y0..y1 and columns x0..x1 (inclusive), zeros elsewhere."""
    img = torch.zeros(1, 1, h, w, dtype=dtype)
    img[..., y0 : y1 + 1, x0 : x1 + 1] = 1.0
    return img


# Boxes and frames chosen so that the scale (frame extent - 1) / (box extent - 1) is an
# integer: the box corners then land on pixel centres and the object region is exactly 1.
@DTYPES
@pytest.mark.parametrize(
    ("frame", "rect"),
    [
        ((33, 33), (10, 14, 8, 16)),  # wide box, square frame: scale 4, width fills
        ((33, 33), (3, 19, 20, 22)),  # tall box, square frame: scale 2, height fills
        ((33, 49), (10, 14, 20, 28)),  # wide frame: width limits, scale 6
        ((33, 49), (2, 10, 30, 32)),  # tall box in a wide frame: height limits, scale 4
    ],
    ids=["wide-square", "tall-square", "wide-wide", "tall-wide"],
)
def test_small_rectangle_fills_frame(
    dtype: torch.dtype, frame: tuple[int, int], rect: tuple[int, int, int, int]
) -> None:
    h, w = frame
    y0, y1, x0, x1 = rect
    img = rectangle(h, w, *rect, dtype)
    out = normalize_extent(img, foreground_mask(img))
    assert out.shape == img.shape and out.dtype == dtype

    oy0, oy1, ox0, ox1 = box(out[0, 0] >= 1 - 10 * IDENTITY_ATOL[dtype])
    scale = min((w - 1) / (x1 - x0), (h - 1) / (y1 - y0))
    # The longer side (relative to the frame) spans the frame ...
    if (w - 1) / (x1 - x0) <= (h - 1) / (y1 - y0):
        assert (ox0, ox1) == (0, w - 1)
    else:
        assert (oy0, oy1) == (0, h - 1)
    # ... the box is centred ...
    assert (ox0 + ox1) / 2 == pytest.approx((w - 1) / 2)
    assert (oy0 + oy1) / 2 == pytest.approx((h - 1) / 2)
    # ... and the aspect ratio is kept.
    assert ox1 - ox0 == pytest.approx(scale * (x1 - x0))
    assert oy1 - oy0 == pytest.approx(scale * (y1 - y0))
    # Nothing brighter than the object appears, nothing negative.
    assert float(out.max()) <= 1 + IDENTITY_ATOL[dtype] and float(out.min()) >= -IDENTITY_ATOL[dtype]


@DTYPES
def test_already_normalized_is_unchanged(dtype: torch.dtype) -> None:
    h = w = 33
    images = rand(3, 2, h, w, seed=0, dtype=dtype)
    masks = torch.zeros(3, h, w, dtype=torch.bool)
    masks[0, 8:25, :] = True  # spans the width, centred vertically
    masks[1, :, 4:29] = True  # spans the height, centred horizontally
    masks[2, :, :] = True  # the whole frame
    masks[0, 16, 16] = False  # holes inside the box do not matter
    out = normalize_extent(images, masks)
    torch.testing.assert_close(out, images, atol=IDENTITY_ATOL[dtype], rtol=0)


@DTYPES
def test_empty_mask_is_unchanged(dtype: torch.dtype) -> None:
    images = rand(2, 1, 16, 20, seed=1, dtype=dtype)
    masks = torch.zeros(2, 16, 20, dtype=torch.bool)
    torch.testing.assert_close(normalize_extent(images, masks), images, atol=IDENTITY_ATOL[dtype], rtol=0)


def test_empty_batch() -> None:
    out = normalize_extent(torch.zeros(0, 1, 8, 8), torch.zeros(0, 8, 8, dtype=torch.bool))
    assert out.shape == (0, 1, 8, 8)


@DTYPES
def test_linear_in_image(dtype: torch.dtype) -> None:
    x = rand(4, 3, 20, 24, seed=2, dtype=dtype)
    y = rand(4, 3, 20, 24, seed=3, dtype=dtype)
    masks = torch.zeros(4, 20, 24, dtype=torch.bool)
    masks[0, 5:9, 3:17] = True
    masks[1, 2:18, 10:13] = True
    masks[2, 7, 7] = True  # a single pixel: the box is clamped to one pixel
    # masks[3] stays empty
    a, b = 0.7, -1.3
    lhs = normalize_extent(a * x + b * y, masks)
    rhs = a * normalize_extent(x, masks) + b * normalize_extent(y, masks)
    torch.testing.assert_close(lhs, rhs, **TOL[dtype])


def _remap_reference(images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """normalize_extent written as kornia's remap of the whole (P, H, W) maps, the box rule
    read from the masks with plain Python: the reference the fast path must equal."""
    p, _, h, w = images.shape
    dtype = images.dtype
    map_x = torch.empty(p, h, w, dtype=dtype)
    map_y = torch.empty(p, h, w, dtype=dtype)
    for i in range(p):
        y0, y1, x0, x1 = box(masks[i])
        box_w = torch.tensor(max(x1 - x0, 1), dtype=dtype)
        box_h = torch.tensor(max(y1 - y0, 1), dtype=dtype)
        fills = [(n - 1) / b for n, b in ((w, box_w), (h, box_h)) if n > 1] or [torch.ones((), dtype=dtype)]
        scale = fills[0] if len(fills) == 1 else torch.minimum(*fills)
        cx, cy = torch.tensor(x0 + x1, dtype=dtype) / 2, torch.tensor(y0 + y1, dtype=dtype) / 2
        u, v = torch.arange(w, dtype=dtype), torch.arange(h, dtype=dtype)
        map_x[i] = (cx + (u - (w - 1) / 2) / scale).expand(h, w)
        map_y[i] = (cy + (v - (h - 1) / 2) / scale)[:, None].expand(h, w)
    return remap(images, map_x, map_y, mode="bilinear", padding_mode="zeros", align_corners=True)


@DTYPES
@pytest.mark.parametrize("shape", [(6, 1, 128, 128), (4, 3, 33, 49), (3, 2, 1, 17), (3, 1, 9, 1)])
def test_equals_kornia_remap_bit_for_bit(dtype: torch.dtype, shape: tuple[int, int, int, int]) -> None:
    # The maps are separable, so normalize_extent normalizes W + H coordinates and calls
    # grid_sample itself; the samples must be remap's exactly, on a strided channel slice
    # as synthesize_views passes it, singleton axes included.
    p, c, h, w = shape
    gen = torch.Generator().manual_seed(7)
    images = rand(p, c + 1, h, w, seed=3, dtype=dtype)[:, :c]
    masks = torch.zeros(p, h, w, dtype=torch.bool)
    for i in range(p):
        y0 = int(torch.randint(0, h, (1,), generator=gen))
        x0 = int(torch.randint(0, w, (1,), generator=gen))
        masks[i, y0 : y0 + max(1, h // 3), x0 : x0 + max(1, w // 2)] = True
    out = normalize_extent(images, masks)
    assert not torch.equal(out, images) or (h, w) == (1, 1)
    assert torch.equal(out, _remap_reference(images, masks))


def test_input_not_modified_and_batched_equals_single() -> None:
    x = rand(3, 1, 20, 24, seed=4)
    masks = x[:, 0] > 0.8
    before = x.clone()
    out = normalize_extent(x, masks)
    torch.testing.assert_close(x, before, atol=0, rtol=0)
    single = torch.cat([normalize_extent(x[i : i + 1], masks[i : i + 1]) for i in range(3)])
    torch.testing.assert_close(out, single, atol=1e-12, rtol=0)


@pytest.mark.parametrize(
    "mask_shape",
    [(2, 16, 15), (2, 15, 16), (1, 16, 16), (16, 16), (2, 1, 16, 16)],
    ids=["width", "height", "batch", "unbatched", "channel"],
)
def test_wrong_mask_shape(mask_shape: tuple[int, ...]) -> None:
    images = torch.zeros(2, 1, 16, 16)
    with pytest.raises(ValueError, match=r"masks must have shape \(P, H, W\) = \(2, 16, 16\)"):
        normalize_extent(images, torch.zeros(mask_shape, dtype=torch.bool))


def test_image_errors() -> None:
    with pytest.raises(ValueError, match=r"images must have shape \(P, C, H, W\)"):
        normalize_extent(torch.zeros(1, 16, 16), torch.zeros(1, 16, 16, dtype=torch.bool))
    with pytest.raises(TypeError, match="images must have a floating dtype"):
        normalize_extent(torch.zeros(1, 1, 4, 4, dtype=torch.uint8), torch.zeros(1, 4, 4, dtype=torch.bool))
    with pytest.raises(TypeError, match=r"images must be a torch\.Tensor"):
        foreground_mask([[0.0]])  # type: ignore[arg-type]


def test_foreground_mask_threshold() -> None:
    # Strictly above the threshold is foreground; 0.25 and its channel mean are exact in binary.
    images = torch.tensor([0.0, 0.25, 0.25 + 1e-6, 0.5], dtype=torch.float64).view(1, 1, 1, 4)
    rgb = images.expand(1, 3, 1, 4)
    for x in (images, rgb):
        mask = foreground_mask(x, threshold=0.25)
        assert mask.shape == (1, 1, 4) and mask.dtype == torch.bool
        assert mask.flatten().tolist() == [False, False, True, True]
    assert foreground_mask(images).flatten().tolist() == [False, True, True, True]  # default 0.05
    assert foreground_mask(images, threshold=0.4).flatten().tolist() == [False, False, False, True]
    assert foreground_mask(images, threshold=-1.0).all()


def test_foreground_mask_averages_channels_and_keeps_leading_dims() -> None:
    images = torch.zeros(2, 5, 3, 4, 6)
    images[..., 0, 1, 2] = 0.3  # one channel at 0.3: mean 0.1 > 0.05
    images[..., 1, 2, 3] = 0.12  # mean 0.04: background
    mask = foreground_mask(images)
    assert mask.shape == (2, 5, 4, 6)
    assert mask[..., 1, 2].all() and not mask[..., 2, 3].any()
    assert int(mask.sum()) == 10


def test_box_fill_is_the_longer_side_of_the_box() -> None:
    masks = torch.zeros(3, 11, 21, dtype=torch.bool)
    masks[0, 2:9, 0:21] = True  # spans the width: 20 / 20
    masks[1, 0:11, 5:8] = True  # spans the height: 10 / 10
    masks[2, 3:6, 5:16] = True  # 10 / 20 wide, 2 / 10 high
    assert box_fill(masks).tolist() == pytest.approx([1.0, 1.0, 0.5])
    assert box_fill(torch.zeros(1, 4, 4, dtype=torch.bool)).tolist() == [0.0]


def test_resolve_extent_auto_follows_the_seeds_fill() -> None:
    filled = torch.zeros(2, 16, 16, dtype=torch.bool)
    filled[:, 0:16, 4:12] = True  # a size-normalized data set's views (COIL's)
    margin = torch.zeros(2, 16, 16, dtype=torch.bool)
    margin[:, 3:13, 4:12] = True  # a photograph: 9 / 15 of the frame
    assert resolve_extent("auto", filled) and not resolve_extent("auto", margin)
    mixed = torch.stack([filled[0], margin[0]])  # one seed with a margin: not a normalized set
    assert not resolve_extent("auto", mixed)
    assert resolve_extent(True, margin) and not resolve_extent(False, filled)
    assert 0.5 < FILLED_FRAME < 1.0


def test_one_pixel_high_or_wide_images_fill_along_their_long_side() -> None:
    """A side one pixel long has no extent: the other sets the scale (it used to be 0, giving NaN)."""
    row = torch.zeros(1, 1, 1, 8, dtype=torch.float64)
    row[..., 2:5] = torch.tensor([0.5, 1.0, 0.7], dtype=torch.float64)
    out = normalize_extent(row, row[:, 0] > 0.1)
    assert torch.isfinite(out).all()
    assert out[0, 0, 0, 0] == 0.5 and out[0, 0, 0, -1] == 0.7  # the box spans the frame
    column = normalize_extent(row.transpose(-1, -2), row.transpose(-1, -2)[:, 0] > 0.1)
    torch.testing.assert_close(column, out.transpose(-1, -2))
    pixel = torch.full((1, 1, 1, 1), 0.5, dtype=torch.float64)
    assert torch.equal(normalize_extent(pixel, pixel[:, 0] > 0.1), pixel)
