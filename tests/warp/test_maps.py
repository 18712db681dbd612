"""The orthographic warp's target→source maps: layout, weights, fallbacks, depth and 2D maps."""

from __future__ import annotations

import math

import torch

from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.warp.maps import WarpMaps
from torch_eigview.warp.novel_view import NovelViewWarp
from torch_eigview.warp.refine import field_sampler

from tests.helpers import rand

ALPHA = 20.0


# --- the maps ---------------------------------------------------------------------------


def test_maps_layout_and_weights(dtype: torch.dtype, device: torch.device) -> None:
    b, h, w = 2, 5, 11
    d12 = (3.0 * rand(b, h, w, seed=5) - 1.5).to(device=device, dtype=dtype)
    corr = correspondence_from_disparity(d12)
    thetas = [-5.0, 0.0, 7.5, 20.0]
    maps = NovelViewWarp(15.0).maps(corr, thetas)
    assert isinstance(maps, WarpMaps) and maps.n_sources == 2 and maps.src_y is None
    for t in (maps.src_x, maps.weight, maps.hit):
        assert t.shape == (2, b, len(thetas), h, w) and t.device.type == device.type
    assert maps.src_x.dtype == maps.weight.dtype == dtype and maps.hit.dtype == torch.bool
    assert torch.equal(maps.thetas, torch.tensor(thetas, dtype=torch.float64))
    assert bool(torch.isfinite(maps.src_x).all())  # holes are filled
    torch.testing.assert_close(maps.weight.sum(0), torch.ones_like(maps.weight[0]))
    assert bool((maps.weight >= 0).all()) and bool((maps.weight <= 1).all())
    # Where only one view sees a pixel it is used alone.
    only1 = maps.hit[0] & ~maps.hit[1]
    only2 = maps.hit[1] & ~maps.hit[0]
    assert bool((maps.weight[0][only1] == 1).all()) and bool((maps.weight[1][only2] == 1).all())
    single = NovelViewWarp(15.0).maps(corr, thetas, n_sources=1)
    assert single.n_sources == 1 and bool((single.weight == 1).all())
    assert torch.equal(single.src_x[0], maps.src_x[0])
    # apply_maps with the precomputed maps is forward().
    views = rand(2, b, 3, h, w, seed=6, dtype=dtype, device=device)
    torch.testing.assert_close(
        NovelViewWarp.apply_maps(maps, views),
        NovelViewWarp(15.0)(views[0], views[1], correspondence=corr, thetas=thetas),
        atol=0,
        rtol=0,
    )


def test_no_correspondence_moves_as_plane_through_axis() -> None:
    """With no trusted match anywhere each view moves as the plane Z = 0: a view-1 pixel at
    X lands at c + X cos(theta), a view-2 pixel at c + X cos(theta) / cos(alpha)."""
    h, w = 3, 11
    corr = correspondence_from_disparity(
        torch.zeros(1, h, w, dtype=torch.float64),
        valid_12=torch.zeros(1, h, w),
        valid_21=torch.zeros(1, h, w),
    )
    thetas = [-25.0, 8.0, 30.0]
    maps = NovelViewWarp(ALPHA).maps(corr, thetas)
    assert not bool(maps.hit.any())
    x = torch.arange(w, dtype=torch.float64) - (w - 1) / 2
    for i, theta in enumerate(thetas):
        th, al = math.radians(theta), math.radians(ALPHA)
        torch.testing.assert_close(maps.src_x[0, 0, i], ((w - 1) / 2 + x / math.cos(th)).expand(h, w))
        torch.testing.assert_close(
            maps.src_x[1, 0, i], ((w - 1) / 2 + x * math.cos(al) / math.cos(th)).expand(h, w)
        )
        lam = min(max(theta / ALPHA, 0.0), 1.0)  # neither view sees it: weights by angle
        torch.testing.assert_close(
            maps.weight[:, 0, i], torch.tensor([1 - lam, lam]).double().view(2, 1, 1).expand(2, h, w)
        )


# --- occlusions: a strip in front of a background plane ---------------------------------

ZF, ZB, HALF = 8.0, -6.0, 7.0  # strip depth, background depth, strip half-width
HO, WO = 12, 64


def _layers(phi_deg: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per column of the view at phi: the strip's X, the background's X, and strip-in-front."""
    phi = math.radians(phi_deg)
    x = torch.arange(WO, dtype=torch.float64) - (WO - 1) / 2
    xf = (x - ZF * math.sin(phi)) / math.cos(phi)
    xb = (x - ZB * math.sin(phi)) / math.cos(phi)
    return xf, xb, xf.abs() <= HALF


def _render_layers(phi_deg: float) -> torch.Tensor:
    xf, xb, front = _layers(phi_deg)
    y = torch.arange(HO, dtype=torch.float64)[:, None]
    strip = 0.6 + 0.3 * torch.sin(xf / 1.7) * torch.cos(y / 2.9)
    back = 0.35 + 0.25 * torch.cos(xb / 2.3 + 0.5) * torch.sin(y / 3.3 + 1)
    return torch.where(front, strip, back)[None]


def test_zbuffer_keeps_the_nearer_surface() -> None:
    """View 1 alone, every in-image match trusted: at theta = alpha the background the strip
    covers maps onto the strip's pixels too, and the depth test must keep the strip."""
    xf, xb, front = _layers(0.0)
    big_x, big_z = torch.where(front, xf, xb), torch.where(front, ZF, ZB)
    al = math.radians(ALPHA)
    d12 = (big_x * math.cos(al) + big_z * math.sin(al) - big_x).expand(HO, WO)[None]
    cols = torch.arange(WO, dtype=torch.float64)
    valid = ((cols + d12) >= 0) & ((cols + d12) <= WO - 1)
    corr = Correspondence(d12, -d12, valid, valid)
    view1, ref = _render_layers(0.0), _render_layers(ALPHA)
    strip = _layers(ALPHA)[2].clone()
    strip[[0, -1]] = False
    strip = strip & ~torch.roll(~strip, 1) & ~torch.roll(~strip, -1)  # 1 px off its edges
    errors = {}
    for sign in (1, -1):
        out = NovelViewWarp(ALPHA, depth_sign=sign)(view1, correspondence=corr, thetas=ALPHA)[0]
        errors[sign] = float((out - ref)[0][:, strip].abs().mean())
    assert errors[1] < 0.01
    assert errors[-1] > 0.05  # the wrong depth sign shows the background through the strip


# --- a tilted camera: 2D maps -------------------------------------------------------

ELEVATION = 30.0


def test_elevation_gives_2d_maps() -> None:
    corr = correspondence_from_disparity(2.0 * rand(2, 5, 8, seed=14) - 1.0)
    assert NovelViewWarp(ALPHA).maps(corr, [3.0]).src_y is None
    maps = NovelViewWarp(ALPHA, elevation=ELEVATION).maps(corr, [3.0, 9.0])
    assert maps.src_y is not None and maps.src_y.shape == maps.src_x.shape == (2, 2, 2, 5, 8)
    assert maps.src_y.dtype == torch.float64 and bool(torch.isfinite(maps.src_y).all())
    assert NovelViewWarp(ALPHA, elevation=ELEVATION).maps(corr, [3.0], n_sources=1).src_y.shape == (
        1,
        2,
        1,
        5,
        8,
    )
    # Zero disparity at theta = 0: nothing moves, also not vertically.
    zero = correspondence_from_disparity(torch.zeros(1, 5, 8, dtype=torch.float64))
    maps = NovelViewWarp(ALPHA, elevation=ELEVATION).maps(zero, [0.0])
    rows = torch.arange(5, dtype=torch.float64)[:, None].expand(5, 8)
    torch.testing.assert_close(maps.src_y[0, 0, 0], rows)


def test_tilted_maps_differentiate_through_the_correspondence() -> None:
    """With an elevation the maps are refined by fixed-point sampling; a correspondence
    that requires grad must still give a graph (the refinement's in-place grid buffer is
    used only without one)."""
    d = (
        torch.rand(8, 10, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 2
    ).requires_grad_()
    corr = correspondence_from_disparity(d, -d.detach())
    view1, view2 = torch.rand(2, 1, 1, 8, 10, dtype=torch.float64)
    out = NovelViewWarp(10.0, elevation=12.0)(view1, view2, correspondence=corr, thetas=[3.0, -4.0])
    out.sum().backward()
    assert d.grad is not None and bool(torch.isfinite(d.grad).all()) and float(d.grad.abs().sum()) > 0
    with torch.no_grad():  # and the in-place path gives the same views
        again = NovelViewWarp(10.0, elevation=12.0)(view1, view2, correspondence=corr, thetas=[3.0, -4.0])
    torch.testing.assert_close(again, out.detach())


def test_map_sampler_differentiates_through_its_fields() -> None:
    """The sampler reuses one grid buffer when nothing is differentiated; with fields that
    need a gradient every call gets its own grid (grid_sample keeps it for backward).

    The private sampler is tested directly: through the public API a correspondence that
    needs a gradient differentiates the sampled coordinates too, so no public call reaches
    the case where only the fields do.
    """
    fields = torch.rand(1, 2, 8, 8, dtype=torch.float64, requires_grad=True)
    sample = field_sampler(fields, 2)
    x, y = torch.rand(1, 2, 8, 8, dtype=torch.float64) * 7, torch.rand(1, 2, 8, 8, dtype=torch.float64) * 7
    (sample(x, y).sum() + sample(x.flip(-1), y).sum()).backward()
    assert fields.grad is not None and bool(fields.grad.abs().sum() > 0)
