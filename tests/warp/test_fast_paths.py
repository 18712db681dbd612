"""The fast map building and sampling against the code they replaced, kept here as the reference.

``fill_row_holes`` (the gaps between hits gathered alone) and ``ViewWarp.apply_maps`` (one ``grid_sample`` for all
sources and angles) must equal the former implementations bit for bit; the 2D refinement,
which now samples one shared disparity field instead of T stacked displacement fields,
equals the former one up to float rounding, and its early stop at a fixed point changes
nothing.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest
import torch
import torch.nn.functional as F
from kornia.geometry.transform import remap

from torch_eigview.geometry.correspondence import correspondence_from_disparity
from torch_eigview.geometry.row_maps import fill_row_holes, invert_row_map
from torch_eigview.warp.maps import RowGeometry, WarpMaps
from torch_eigview.warp.novel_view import NovelViewWarp
from torch_eigview.warp.refine import refine_2d

from tests.helpers import rand


# --- the former implementations -------------------------------------------------------
def _old_sampler(fields: torch.Tensor) -> Callable[..., torch.Tensor]:
    """Bilinear sampler of ``fields`` (B, T, F, H, W) at pixel coordinates (B, T, H, W).

    These are maps, not images: sampled with ``grid_sample`` directly (border padding,
    ``align_corners=True``, the convention kornia's ``remap`` uses for pixel maps), the
    first ``n_fields`` of the F fields (default all) in one call.
    """
    b, t, f, h, w = fields.shape
    flat = fields.reshape(b * t, f, h, w)
    sx, sy = 2.0 / max(w - 1, 1), 2.0 / max(h - 1, 1)
    grid = fields.new_empty(b, t, h, w, 2)  # written in place on every call

    def sample(x: torch.Tensor, y: torch.Tensor, n_fields: int = f) -> torch.Tensor:
        if torch.is_grad_enabled() and (x.requires_grad or y.requires_grad or flat.requires_grad):
            # out= does not differentiate, and grid_sample keeps its grid for the backward
            # pass, so a differentiated call gets a grid of its own.
            g = torch.stack([x * sx - 1, y * sy - 1], dim=-1)
        else:
            torch.mul(x, sx, out=grid[..., 0]).sub_(1)
            torch.mul(y, sy, out=grid[..., 1]).sub_(1)
            g = grid
        src = flat if n_fields == f else flat[:, :n_fields]
        out = F.grid_sample(
            src, g.view(b * t, h, w, 2), mode="bilinear", padding_mode="border", align_corners=True
        )
        return out.view(b, t, n_fields, h, w)

    return sample


def _old_refine_2d(
    src_x: torch.Tensor, dx: torch.Tensor, dy: torch.Tensor, valid: torch.Tensor, iters: int = 4
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Inverts the 2D forward map p -> p + (dx, dy)(p) by fixed-point iteration.

    Starts from the row-wise inverse ``src_x``; a target pixel is a hit when the iteration
    lands on a valid source pixel that maps back to within half a pixel.
    """
    b, t, h, w = dx.shape
    xx = torch.arange(w, dtype=dx.dtype, device=dx.device).expand(b, t, h, w)
    yy = torch.arange(h, dtype=dx.dtype, device=dx.device).view(h, 1).expand(b, t, h, w)
    valid_t = (valid[:, None] if valid.ndim == 3 else valid).to(dx.dtype).expand(b, t, h, w)
    sample = _old_sampler(torch.stack([dx, dy, valid_t], dim=2))
    sx, sy = src_x, yy - dy
    for _ in range(iters):
        d = sample(sx, sy, 2)  # the displacement only; validity once, at the end
        sx, sy = xx - d[:, :, 0], yy - d[:, :, 1]
    d = sample(sx, sy)
    residual = (sx + d[:, :, 0] - xx).abs() + (sy + d[:, :, 1] - yy).abs()
    inside = (sx >= 0) & (sx <= w - 1) & (sy >= 0) & (sy <= h - 1)
    return sx, sy, (d[:, :, 2] > 0.999) & inside & (residual < 0.5)


def _old_source_maps(
    self: RowGeometry, x1: torch.Tensor, x2: torch.Tensor, valid: torch.Tensor, second: bool
) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
    """Maps for one seed view as the source; ``x1``, ``x2`` (B, H, W) are matching columns
    in view 1 and view 2, on the pixel grid of the source view (view 2 if ``second``)."""
    c, al, th = self.c, self.alpha, self.theta
    big_x = (x1 - c)[:, None]
    big_z = ((x2 - c)[:, None] - big_x * math.cos(al)) / math.sin(al)
    dst_x_for_src = c + self.a * (x1 - c)[:, None] + self.b * (x2 - c)[:, None]
    depth = self.sign * (big_z * torch.cos(th) - big_x * torch.sin(th))
    # Where the other view's coefficient vanishes (theta at this seed's own angle) the map
    # needs no correspondence: every pixel is trusted, and the seed view is reproduced.
    other = self.a if second else self.b
    valid = valid[:, None] | (other == 0)
    src_x, hit = invert_row_map(dst_x_for_src, valid, depth, self.max_stretch)
    # Without a correspondence a pixel moves as a plane through the axis (Z = 0).
    scale = (math.cos(al) if second else 1.0) / torch.cos(th).clamp_min(1e-6)
    cols = torch.arange(x1.shape[-1], dtype=x1.dtype, device=x1.device)
    src_x = fill_row_holes(src_x, hit, (c + (cols - c) * scale).expand_as(src_x))
    if self.tilt == 0.0:
        return src_x, None, hit
    phi = al if second else 0.0
    dy = -self.tilt * (big_z * (torch.cos(th) - math.cos(phi)) - big_x * (torch.sin(th) - math.sin(phi)))
    grid = x2 if second else x1
    return _old_refine_2d(src_x, dst_x_for_src - grid[:, None], dy, valid)


def _old_fill_row_holes(src: torch.Tensor, hit: torch.Tensor, fallback: torch.Tensor) -> torch.Tensor:
    """Fills non-hit target pixels by interpolating the map between hits along the row.

    Beyond the last hit of a row the fallback map, shifted to meet that hit, continues
    it; a row with no hit takes the fallback map.
    """
    w = src.shape[-1]
    cols = torch.arange(w, device=src.device).expand_as(hit)
    prev = torch.where(hit, cols, -1).cummax(dim=-1).values
    nxt = torch.where(hit, cols, w).flip(-1).cummin(dim=-1).values.flip(-1)
    has_prev, has_next = prev >= 0, nxt < w
    p, n = prev.clamp(0, w - 1), nxt.clamp(0, w - 1)
    sp, sn = src.gather(-1, p), src.gather(-1, n)
    fp, fn = fallback.gather(-1, p), fallback.gather(-1, n)
    span = (n - p).clamp_min(1).to(src.dtype)
    between = sp + (sn - sp) * (cols - p).to(src.dtype) / span
    left_only = fallback + (sp - fp)
    right_only = fallback + (sn - fn)
    filled = torch.where(has_prev & has_next, between, torch.where(has_prev, left_only, right_only))
    filled = torch.where(has_prev | has_next, filled, fallback)
    return torch.where(hit, src, filled)


def _old_apply_maps(maps: WarpMaps, views: torch.Tensor) -> torch.Tensor:
    """The former sampling: kornia's remap per source on T copies of each seed."""
    s, b, t, h, w = maps.src_x.shape
    ch = views.shape[2]
    rows = torch.arange(h, dtype=views.dtype).view(1, h, 1).expand(b * t, h, w)
    out = views.new_zeros(b, t, ch, h, w)
    for i in range(s):
        img = views[i][:, None].expand(b, t, ch, h, w).reshape(b * t, ch, h, w)
        map_x = maps.src_x[i].reshape(b * t, h, w).to(views.dtype)
        map_y = rows if maps.src_y is None else maps.src_y[i].reshape(b * t, h, w).to(views.dtype)
        warped = remap(img, map_x, map_y, mode="bilinear", padding_mode="zeros", align_corners=True)
        out = out + maps.weight[i].to(views.dtype)[:, :, None] * warped.view(b, t, ch, h, w)
    return out


# --- the comparisons --------------------------------------------------------------------


def _corr(b: int, h: int, w: int, seed: int, dtype: torch.dtype) -> object:
    d = (4.0 * rand(b, h, w, seed=seed) - 2.0).to(dtype)
    corr = correspondence_from_disparity(d)
    corr.valid_12[:, :, : w // 5] = False  # an untrusted band: holes, the fallback map
    return corr


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("hit_rate", [0.0, 0.3, 0.95, 1.0])
def test_fill_row_holes_equals_former_bit_for_bit(dtype: torch.dtype, hit_rate: float) -> None:
    g = torch.Generator().manual_seed(3)
    src = torch.rand(2, 3, 7, 19, generator=g, dtype=dtype) * 18
    hit = torch.rand(2, 3, 7, 19, generator=g) < hit_rate
    hit[0, 0, 0] = False  # a row with no hit
    src = torch.where(hit, src, math.nan)
    fallback = (torch.arange(19, dtype=dtype) * 0.9 + 0.5).expand_as(src)  # expanded, not copied
    assert torch.equal(fill_row_holes(src, hit, fallback), _old_fill_row_holes(src, hit, fallback))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fill_row_holes_object_rows_equal_former_bit_for_bit(dtype: torch.dtype) -> None:
    """Hits in runs with gaps (an object's rows on a background), as the warp's maps have
    them: interiors interpolated, exteriors shifted, empty rows the fallback, bit for bit."""
    g = torch.Generator().manual_seed(5)
    b, h, w = 3, 9, 23
    start = torch.randint(0, w, (b, 1, h, 1), generator=g)
    stop = start + torch.randint(0, w, (b, 1, h, 1), generator=g)
    cols = torch.arange(w)
    hit = (cols >= start) & (cols < stop) & (torch.rand(b, 1, h, w, generator=g) < 0.8)
    src = torch.where(hit, torch.rand(b, 1, h, w, generator=g, dtype=dtype) * 20, math.nan)
    scale = 1 + torch.rand(b, 1, 1, 1, generator=g, dtype=dtype)
    fallback = (7.0 + (torch.arange(w, dtype=dtype) - 7.0) * scale).expand_as(src)
    assert torch.equal(fill_row_holes(src, hit, fallback), _old_fill_row_holes(src, hit, fallback))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("size", [(12, 17), (128, 128), (1, 9)])
@pytest.mark.parametrize("tilt_deg", [0.0, 14.0])
@pytest.mark.parametrize("shared", [True, False])
def test_apply_maps_equals_kornia_remap_bit_for_bit(
    tilt_deg: float, shared: bool, size: tuple[int, int], dtype: torch.dtype
) -> None:
    """The view sampler (grid_sample on coordinates normalized by the copy of kornia's
    rule) gives kornia's remap's samples bit for bit, a single row included."""
    b, (h, w) = 2, size
    corr = _corr(b, h, w, 1, dtype)
    thetas = [-8.0, 0.0, 4.0, 11.0] if shared else torch.tensor([[-8.0, 3.0], [5.0, 12.0]])
    maps = NovelViewWarp(10.0, elevation=tilt_deg).maps(corr, thetas)
    views = torch.rand(2, b, 3, h, w, generator=torch.Generator().manual_seed(2), dtype=dtype)
    assert torch.equal(NovelViewWarp.apply_maps(maps, views), _old_apply_maps(maps, views))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_kornia_scale_is_kornias_normalization_bit_for_bit(dtype: torch.dtype) -> None:
    """The sampler's copy of kornia's pixel normalization gives what
    ``kornia.geometry.conversions.normalize_pixel_coordinates`` gives, on every axis length
    up to 4,096 and a single pixel, at coordinates inside and outside the image."""
    from kornia.geometry.conversions import normalize_pixel_coordinates

    from torch_eigview.warp.base import kornia_scale

    gen = torch.Generator().manual_seed(4)
    for n in [*range(1, 300), 511, 512, 1023, 1024, 2047, 2048, 4095, 4096]:
        x = (torch.rand(64, generator=gen, dtype=torch.float64) * (n + 4) - 2).to(dtype)
        factor, offset = kornia_scale(n, x)
        want = normalize_pixel_coordinates(torch.stack([x, x], dim=-1), n, n)
        assert torch.equal(x * factor - offset, want[:, 0]), n


def _both_refinements(seed: int, thetas: list[float], second: bool) -> tuple[tuple, tuple]:
    b, h, w = 2, 24, 32
    corr = _corr(b, h, w, seed, torch.float32)
    warp = NovelViewWarp(10.0, elevation=13.0)
    captured: dict[str, RowGeometry] = {}
    original = RowGeometry.maps

    def spy(self: RowGeometry, *args: object, **kwargs: object) -> WarpMaps:
        captured["geo"] = self
        return original(self, *args, **kwargs)

    RowGeometry.maps = spy  # type: ignore[method-assign]
    try:
        warp.maps(corr, thetas)
    finally:
        RowGeometry.maps = original  # type: ignore[method-assign]
    geo = captured["geo"]
    cols = torch.arange(w, dtype=torch.float32).expand(b, h, w)
    if second:
        args = (cols + corr.disparity_21, cols, corr.valid_21)
    else:
        args = (cols, cols + corr.disparity_12, corr.valid_12)
    return geo.source_maps(*args, second=second), _old_source_maps(geo, *args, second=second)


@pytest.mark.parametrize("second", [False, True])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refine_2d_equals_former_up_to_rounding(second: bool, seed: int) -> None:
    """One shared disparity field instead of T stacked fields: the same maps up to float
    rounding. Where a pixel does not converge (no hit) the iteration carries a rounding
    difference on, so there the bound is a thousandth of a pixel."""
    (sx, sy, hit), (ox, oy, ohit) = _both_refinements(seed, [-15.0, -4.0, 0.0, 6.0, 10.0, 19.0], second)
    assert torch.equal(hit, ohit) and bool(hit.any())
    torch.testing.assert_close(sx[hit], ox[hit], atol=1e-4, rtol=0)
    torch.testing.assert_close(sy[hit], oy[hit], atol=1e-4, rtol=0)
    torch.testing.assert_close(sx, ox, atol=1e-3, rtol=0)
    torch.testing.assert_close(sy, oy, atol=1e-3, rtol=0)


def test_refine_2d_stops_at_a_fixed_point_with_the_same_result() -> None:
    """A constant disparity at the seed's own angle converges at once: the early stop
    gives exactly the maps that every further iteration would give again."""
    b, t, h, w = 1, 2, 6, 9
    disparity = torch.full((b, h, w), 0.25)
    zero = torch.zeros(1, t, 1, 1)
    coef = (zero, zero + 0.5, zero, zero - 0.5)  # dx = D / 2, dy = -D / 2: a pure shift
    valid = torch.ones(b, h, w, dtype=torch.bool)
    own = torch.zeros(1, t, 1, 1, dtype=torch.bool)
    start = torch.arange(w, dtype=torch.float32).expand(b, t, h, w) - 0.125
    once = refine_2d(start, disparity, coef, 4.0, valid, own, iters=1)
    many = refine_2d(start, disparity, coef, 4.0, valid, own, iters=50)
    for a, b_ in zip(once, many, strict=True):
        assert torch.equal(a, b_)
    assert bool(once[2][..., 1:-1, 1:-1].all())


@pytest.mark.parametrize("second", [False, True])
@pytest.mark.parametrize("angles", ["shared", "per_object", "own", "view_1_only"])
def test_source_maps_on_a_background_equal_the_whole_grid_maps_bit_for_bit(
    second: bool, angles: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Objects on a background (most pixels invalid): Eq. 2 at the valid pixel pairs alone
    (invert_row_segments) gives the whole-grid maps bit for bit, for T shared angles and
    for each object's own; among shared angles the seed's own (every pixel trusted) take
    the whole grid and the others the pairs, each angle's map as in one whole-grid call."""
    b, h, w = 3, 10, 24
    corr = _corr(b, h, w, 7, torch.float32)
    band = torch.zeros(b, h, w, dtype=torch.bool)
    band[:, :, 6:15] = True  # an object's extent; outside, no correspondence
    corr.valid_12.logical_and_(band)
    corr.valid_21.logical_and_(band)
    thetas = {
        "shared": [-12.0, 6.0, 14.0],
        "per_object": torch.tensor([[-12.0, 4.0], [7.0, 15.0], [-3.0, 9.5]]),
        "own": [-12.0, 0.0, 6.0, 10.0],
        "view_1_only": [0.0],  # view 1's own angle alone: no angle for the pairs
    }[angles]
    warp = NovelViewWarp(10.0)
    captured: dict[str, RowGeometry] = {}
    original = RowGeometry.maps

    def spy(self: RowGeometry, *args: object, **kwargs: object) -> WarpMaps:
        captured["geo"] = self
        return original(self, *args, **kwargs)

    monkeypatch.setattr(RowGeometry, "maps", spy)
    warp.maps(corr, thetas)
    geo = captured["geo"]
    calls: list[int] = []
    import torch_eigview.warp.maps as maps_module

    segments = maps_module.invert_row_segments

    def counted(*args: object, **kwargs: object) -> tuple[torch.Tensor, torch.Tensor]:
        calls.append(1)
        return segments(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(maps_module, "invert_row_segments", counted)
    cols = torch.arange(w, dtype=torch.float32).expand(b, h, w)
    if second:
        args = (cols + corr.disparity_21, cols, corr.valid_21)
    else:
        args = (cols, cols + corr.disparity_12, corr.valid_12)
    src, _, hit = geo.source_maps(*args, second=second)
    ref_src, _, ref_hit = _old_source_maps(geo, *args, second=second)
    # A seed's own angles apart, on the whole grid, the others by segments.
    whole = angles == "view_1_only" and not second  # the seed reproduced: every pixel hit
    assert calls == ([] if whole else [1])
    assert torch.equal(hit, ref_hit) and bool(hit.any()) and bool((~hit).any()) != whole
    assert torch.equal(src, ref_src)


def test_invert_row_map_long_segments_keep_their_z_order() -> None:
    """Slots m >= 1 are scattered after slot 0 (no concatenation): a long near segment
    still wins over a short far one that covers the same column in slot 0."""
    dst = torch.tensor([[[[0.0, 6.0, 2.4, 3.1]]]])  # segment 0 spans 0..6, segment 2 covers 3
    depth = torch.tensor([[[[5.0, 5.0, 0.0, 0.0]]]])
    src, hit = invert_row_map(dst, torch.ones(1, 1, 4, dtype=torch.bool), depth)
    assert bool(hit[0, 0, 0].all())
    torch.testing.assert_close(src[0, 0, 0, 3], torch.tensor(0.5))  # from segment 0, not 2
