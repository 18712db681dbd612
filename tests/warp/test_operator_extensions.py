"""SparseViewOperator beyond one seed pair and plain weights: Sec. 4.1's common factor and
silhouette-aware weights, against the direct form, kornia and a slow loop."""

from __future__ import annotations

import math

import pytest
import torch

from torch_eigview.geometry.correspondence import correspondence_from_disparity
from torch_eigview.warp.maps import WarpMaps
from torch_eigview.warp.novel_view import NovelViewWarp
from torch_eigview.warp.operator import SparseViewOperator

from tests.warp.operator_cases import (
    ALPHA,
    THETAS,
    TOL,
    H,
    W,
    assert_close,
    generator,
    maps_2d,
    setup,
    smooth_disparity,
)


# --------------------------------------------------------------- Sec. 4.1: common factor
def _pair_ops(images: torch.Tensor, layout: str) -> list[SparseViewOperator]:
    """Operators of the consecutive seed pairs (0, 1) and (1, 2) of three seed views."""
    ops = []
    for n in range(images.shape[0] - 1):
        gen = generator(10 + n)
        d12 = smooth_disparity(gen, 2.0, images.dtype)
        maps = NovelViewWarp(ALPHA).maps(correspondence_from_disparity(d12, -d12), THETAS[:4])
        ops.append(SparseViewOperator.from_maps(images[n : n + 2], maps, layout=layout))
    return ops


@pytest.mark.parametrize("layout", ["row", "image"])
@pytest.mark.parametrize("channels", [1, 2])
def test_common_factor_equals_direct_form_with_full_row_rank(layout: str, channels: int) -> None:
    images = torch.rand(3, channels, H, W, generator=generator(3), dtype=torch.float64) + 0.1
    ops = _pair_ops(images, layout)
    direct = SparseViewOperator.concat(ops)
    common = SparseViewOperator.common_factor(ops)
    assert ops[0].full_row_rank()
    assert common.G is ops[0].G and common.n_views == direct.n_views == 8
    assert common.C.shape == (ops[0].G.shape[1], 8)
    torch.testing.assert_close(common.data_matrix(), direct.data_matrix(), rtol=0, atol=1e-12)
    # The first pair's columns are C1 itself; the others are denser.
    assert torch.equal(common.C.to_dense()[:, :4], ops[0].C.to_dense())


def test_common_factor_needs_full_row_rank() -> None:
    """An all-black row in the first pair's seeds (COIL's background) breaks the rank."""
    images = torch.rand(3, 1, H, W, generator=generator(4), dtype=torch.float64) + 0.1
    images[:2, :, 2] = 0.0  # row 2 black in both seeds of the first pair only
    ops = _pair_ops(images, "row")
    assert not ops[0].full_row_rank() and ops[1].full_row_rank()
    direct = SparseViewOperator.concat(ops).views()
    common = SparseViewOperator.common_factor(ops).views()
    # Row 2 of the second pair's views holds the third seed's content, which G1 cannot
    # span: the common form zeroes it; every other row agrees.
    assert float(direct[4:, :, 2].abs().max()) > 0.1
    assert float(common[4:, :, 2].abs().max()) == 0.0
    keep = torch.ones(H, dtype=torch.bool)
    keep[2] = False
    torch.testing.assert_close(common[:, :, keep], direct[:, :, keep], rtol=0, atol=1e-12)
    # Black in every seed (a background row of all views): rank-deficient, yet equal.
    images[2, :, 2] = 0.0
    ops = _pair_ops(images, "row")
    assert not ops[0].full_row_rank()
    torch.testing.assert_close(
        SparseViewOperator.common_factor(ops).views(),
        SparseViewOperator.concat(ops).views(),
        rtol=0,
        atol=1e-12,
    )


# --------------------------------------------------------------------------- silhouette-aware weights
def _blob_masks(n_sources: int, seed: int) -> torch.Tensor:
    """(S, H, W) bool foreground: an off-centre ellipse per seed (a silhouette to cross)."""
    gen = generator(seed)
    yy = torch.arange(H, dtype=torch.float64).view(H, 1)
    xx = torch.arange(W, dtype=torch.float64).view(1, W)
    out = []
    for _ in range(n_sources):
        cy, cx = H / 2 + torch.rand(1, generator=gen).item(), W / 2 + 2 * torch.rand(1, generator=gen).item()
        out.append(((yy - cy) / (0.38 * H)) ** 2 + ((xx - cx) / (0.33 * W)) ** 2 <= 1)
    return torch.stack(out)


def _silhouette_loop(images: torch.Tensor, maps: WarpMaps, masks: torch.Tensor) -> torch.Tensor:
    """Slow reference: per target pixel, the bilinear taps of every source with the blend
    weight, foreground taps only, renormalized; background below a foreground share of 1/2."""
    s, _, t, h, w = maps.src_x.shape
    img, fg = images.double(), masks.double()
    out = torch.zeros(t, images.shape[1], h, w, dtype=torch.float64)
    for ti in range(t):
        for j in range(h):
            for q in range(w):
                num, share = torch.zeros(images.shape[1], dtype=torch.float64), 0.0
                for si in range(s):
                    wt = float(maps.weight[si, 0, ti, j, q])
                    if wt == 0:
                        continue
                    x = float(maps.src_x[si, 0, ti, j, q])
                    y = float(j if maps.src_y is None else maps.src_y[si, 0, ti, j, q])
                    x0, y0 = math.floor(x), math.floor(y)
                    for yy, xx in ((y0, x0), (y0, x0 + 1), (y0 + 1, x0), (y0 + 1, x0 + 1)):
                        tent = (1 - abs(x - xx)) * (1 - abs(y - yy))
                        if 0 <= xx < w and 0 <= yy < h and tent > 0 and fg[si, yy, xx] > 0:
                            num += wt * tent * img[si, :, yy, xx]
                            share += wt * tent
                if share >= 0.5:
                    out[ti, :, j, q] = num / share
    return out.to(images.dtype)


@pytest.mark.parametrize("layout", ["row", "image"])
@pytest.mark.parametrize("n_sources", [1, 2])
def test_silhouette_aware_weights(dtype: torch.dtype, layout: str, n_sources: int) -> None:
    """G·C with masks equals NovelViewWarp.apply_maps with masks and a slow loop, in both
    layouts; no foreground pixel of the result mixes in background."""
    images, maps = setup(dtype, 2, n_sources, amplitude=2.5, seed=3)
    masks = _blob_masks(n_sources, seed=4)
    # Foreground well above 0 and a zero background: a tap of background mixed in would
    # pull a pixel below 0.5.
    images = (images + 0.5) * masks[:, None]
    expected = NovelViewWarp.apply_maps(maps, images[:, None], masks[:, None])[0]
    op = SparseViewOperator.from_maps(images, maps, layout=layout, masks=masks)
    assert_close(op.views(), expected, dtype)
    assert float((expected - _silhouette_loop(images, maps, masks)).abs().max()) <= TOL[dtype]
    fore = expected.amax(dim=1) > 0
    assert bool(fore.any()) and bool((expected.amin(dim=1)[fore] >= 0.5 - TOL[dtype]).all())
    # Without masks the silhouette's pixels mix in the zero background.
    plain = NovelViewWarp.apply_maps(maps, images[:, None])[0]
    assert float(plain.amax(dim=1)[plain.amax(dim=1) > 0].min()) < 0.5


def test_silhouette_aware_2d_maps(dtype: torch.dtype) -> None:
    maps = maps_2d(dtype, 2)
    images = torch.rand(2, 1, H, W, generator=generator(6), dtype=torch.float64).to(dtype) + 0.5
    masks = _blob_masks(2, seed=7)
    expected = NovelViewWarp.apply_maps(maps, images[:, None], masks[:, None])[0]
    assert_close(SparseViewOperator.from_maps(images, maps, masks=masks).views(), expected, dtype)
    assert float((expected - _silhouette_loop(images, maps, masks)).abs().max()) <= TOL[dtype]


def test_silhouette_masks_any_dtype() -> None:
    """Non-zero is foreground in both paths, whatever the masks' dtype (0/255 uint8, 0/0.4 float)."""
    images, maps = setup(torch.float64, 1, 2, seed=8)
    masks = _blob_masks(2, seed=9)
    ref = NovelViewWarp.apply_maps(maps, images[:, None], masks[:, None])[0]
    for m in (masks.to(torch.uint8) * 255, masks.double() * 0.4):
        torch.testing.assert_close(NovelViewWarp.apply_maps(maps, images[:, None], m[:, None])[0], ref)
        torch.testing.assert_close(SparseViewOperator.from_maps(images, maps, masks=m).views(), ref)


def test_silhouette_masks_errors() -> None:
    images, maps = setup(torch.float64, 1, 2)
    with pytest.raises(
        ValueError, match=r"masks must have shape \(S, H, W\) = \(2, 12, 16\), got \(1, 12, 16\)"
    ):
        SparseViewOperator.from_maps(images, maps, masks=torch.ones(1, H, W, dtype=torch.bool))
    with pytest.raises(TypeError, match="masks must be a tensor, got list"):
        SparseViewOperator.from_maps(images, maps, masks=[[1.0]])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"masks must have shape \(S, B, H, W\) = \(2, 1, 12, 16\)"):
        NovelViewWarp.apply_maps(maps, images[:, None], torch.ones(2, H, W))
