"""Novel-view warp: loops against the row-map inversion, analytic scenes against the warp."""

from __future__ import annotations

import math

import pytest
import torch

from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.geometry.pose import estimate_elevation, orthographic_coefficients
from torch_eigview.warp.novel_view import NovelViewWarp

from tests.helpers import check_module, rand

# --- an analytic scene: a textured vertical cylinder on the rotation axis --------------
#
# A point at angle psi on a cylinder of radius R is X = R sin(psi), Z = R cos(psi); the
# camera at phi sees it at x - c = R sin(psi + phi) (Eq. 2's orthographic camera), in front
# when cos(psi + phi) > 0. A camera tilted by `elevation` also moves it vertically:
# y = Y - sin(elevation) (Z cos(phi) - X sin(phi)) = Y - tilt R cos(psi + phi).

H, W = 24, 48
R = 18.0
BG = 0.2
ALPHA = 20.0


def _texture(psi: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    s = R * psi  # arc length in pixels: wavelengths of 14 px and more, smooth for bilinear
    return 0.5 + 0.25 * torch.sin(s / 2.3) * torch.cos(y / 3.1) + 0.15 * torch.cos(s / 4.7 + 0.4)


def _render(phi_deg: float, c: float, tilt: float = 0.0) -> torch.Tensor:
    """(1, H, W) float64 view of the cylinder at angle phi, rendered analytically."""
    x = torch.arange(W, dtype=torch.float64)
    y = torch.arange(H, dtype=torch.float64)[:, None]
    u = ((x - c) / R).clamp(-1, 1)
    psi = torch.asin(u) - math.radians(phi_deg)
    img = _texture(psi, y + tilt * R * torch.sqrt(1 - u**2))
    return torch.where((x - c).abs() < R, img, torch.full((), BG, dtype=torch.float64))[None]


def _cylinder_correspondence(alpha: float, c: float, tilt: float = 0.0) -> Correspondence:
    """(1, H, W) exact correspondences; valid where the point is on the cylinder and seen
    by both views. The background moves as the plane Z = 0 through the axis."""
    al = math.radians(alpha)
    x = torch.arange(W, dtype=torch.float64).expand(H, W)
    on = (x - c).abs() < R
    psi = torch.asin(((x - c) / R).clamp(-1, 1))  # angle in the frame of the view itself
    d12 = torch.where(on, c + R * torch.sin(psi + al) - x, (x - c) * (math.cos(al) - 1))
    d21 = torch.where(on, c + R * torch.sin(psi - al) - x, (x - c) * (1 / math.cos(al) - 1))
    seen_in_2 = on & (torch.cos(psi + al) > 0)
    seen_in_1 = on & (torch.cos(psi - al) > 0)
    dy = -tilt * R * (torch.cos(psi + al) - torch.cos(psi))
    return Correspondence(d12[None], d21[None], seen_in_2[None], seen_in_1[None], dy[None] if tilt else None)


def _inner(c: float, rows: int = 0) -> torch.Tensor:
    """(H, W) pixels on the cylinder away from its silhouette (|x - c| < 0.8 R)."""
    x = torch.arange(W, dtype=torch.float64)
    inner = ((x - c).abs() < 0.8 * R).expand(H, W).clone()
    if rows:
        inner[:rows], inner[-rows:] = False, False
    return inner


def _assert_matches_rendering(out: torch.Tensor, thetas: list[float], c: float, tilt: float = 0.0) -> None:
    """``out`` (T, 1, H, W) against the analytic views: mean error < 1 % of the intensity
    range, max < 4 %, away from the silhouette (the paper: equal except near occlusions)."""
    inner = _inner(c, rows=3 if tilt else 0)
    for view, theta in zip(out, thetas, strict=True):
        ref = _render(theta, c, tilt)
        span = float(ref[0][inner].max() - ref[0][inner].min())
        err = (view.double() - ref).abs()[0][inner]
        assert float(err.mean()) < 0.01 * span, f"theta={theta}: mean error {float(err.mean()):.4f}"
        assert float(err.max()) < 0.04 * span, f"theta={theta}: max error {float(err.max()):.4f}"


@pytest.mark.parametrize("c", [(W - 1) / 2, 20.0])
def test_seed_angles_reproduce_seed_views(c: float, dtype: torch.dtype) -> None:
    center = None if c == (W - 1) / 2 else c
    view1, view2 = _render(0.0, c).to(dtype), _render(ALPHA, c).to(dtype)
    corr = _cylinder_correspondence(ALPHA, c).to(dtype=dtype)
    warp = NovelViewWarp(ALPHA, center)
    exact = dict(atol=1e-12, rtol=0) if dtype == torch.float64 else dict(atol=1e-5, rtol=0)
    out = warp(view1, view2, correspondence=corr, thetas=[0.0, ALPHA])
    assert out.shape == (2, 1, H, W) and out.dtype == dtype
    torch.testing.assert_close(out[0], view1, **exact)
    torch.testing.assert_close(out[1], view2, **exact)
    torch.testing.assert_close(warp(view1, correspondence=corr, thetas=0.0)[0], view1, **exact)


@pytest.mark.parametrize("c", [(W - 1) / 2, 20.0])
@pytest.mark.parametrize("masks", ["visibility", "consistency"])
def test_matches_analytic_rendering(c: float, masks: str, dtype: torch.dtype) -> None:
    """Synthesized views equal the real ones except near occlusions, inside [0, alpha] and out."""
    center = None if c == (W - 1) / 2 else c
    corr = _cylinder_correspondence(ALPHA, c)
    if masks == "consistency":  # let the forward–backward check find the hidden points
        corr = correspondence_from_disparity(corr.disparity_12, corr.disparity_21)
    corr = corr.to(dtype=dtype)
    view1, view2 = _render(0.0, c).to(dtype), _render(ALPHA, c).to(dtype)
    thetas = [-10.0, 5.0, 10.0, 15.0, 30.0]
    warp = NovelViewWarp(ALPHA, center)
    out = warp(view1[None], view2[None], correspondence=corr, thetas=thetas)
    assert out.shape == (1, len(thetas), 1, H, W) and out.dtype == dtype
    _assert_matches_rendering(out[0], thetas, c)
    # View 1 alone sees the inner part of the views from -10 to 15 degrees well away from its
    # own silhouette (at alpha, the left end of the inner part comes from 1 px off the limb).
    one = [-10.0, 5.0, 10.0, 15.0]
    _assert_matches_rendering(warp(view1, correspondence=corr, thetas=one), one, c)


def test_seed_angles_need_no_trusted_match(dtype: torch.dtype) -> None:
    """At theta = 0 (alpha) the map of view 1 (2) is the identity whatever the masks say, so
    the seed view comes back even where its correspondences are not trusted."""
    h, w = 4, 12
    view1, view2 = rand(2, 1, h, w, seed=16, dtype=dtype), rand(2, 1, h, w, seed=17, dtype=dtype)
    d12 = (4.0 * rand(2, h, w, seed=18) - 2.0).to(dtype)
    masks = [rand(2, h, w, seed=s) > 0.5 for s in (19, 20)]
    corr = correspondence_from_disparity(d12, -d12, valid_12=masks[0], valid_21=masks[1])
    out = NovelViewWarp(ALPHA)(view1, view2, correspondence=corr, thetas=[0.0, ALPHA])
    torch.testing.assert_close(out[:, 0], view1, atol=1e-6 if dtype == torch.float32 else 1e-12, rtol=0)
    torch.testing.assert_close(out[:, 1], view2, atol=1e-6 if dtype == torch.float32 else 1e-12, rtol=0)


def test_zero_disparity_views_and_foreshortening(dtype: torch.dtype, tol: dict[str, float]) -> None:
    """Zero disparity is the plane Z = X tan(alpha / 2): theta = 0 and alpha give the seed
    views whatever they hold, and in between the image is scaled about the axis by a + b."""
    h, w = 5, 13
    view1, view2 = rand(2, 3, h, w, seed=1, dtype=dtype), rand(2, 3, h, w, seed=2, dtype=dtype)
    corr = correspondence_from_disparity(torch.zeros(2, h, w, dtype=dtype))
    warp = NovelViewWarp(ALPHA)
    out = warp(view1, view2, correspondence=corr, thetas=[0.0, ALPHA])
    torch.testing.assert_close(out[:, 0], view1, **tol)
    torch.testing.assert_close(out[:, 1], view2, **tol)
    # A ramp p + q (x - c) + r y is sampled exactly by bilinear interpolation, so the novel
    # view is p + q (x - c) / (a + b) + r y wherever the source is inside the image.
    c = (w - 1) / 2
    x = torch.arange(w, dtype=torch.float64)
    y = torch.arange(h, dtype=torch.float64)[:, None]
    ramp = (0.5 + 0.05 * (x - c) + 0.01 * y).expand(1, 1, h, w)
    thetas = [-15.0, 4.0, 10.0, 35.0]
    a, b = orthographic_coefficients(thetas, ALPHA)
    corr1 = correspondence_from_disparity(torch.zeros(1, h, w, dtype=dtype))
    maps = warp.maps(corr1, thetas)
    out = warp(ramp.to(dtype), ramp.to(dtype), correspondence=corr1, thetas=thetas)[0, :, 0].double()
    for i in range(len(thetas)):
        expected = 0.5 + 0.05 * (x - c) / (a[i] + b[i]) + 0.01 * y
        seen = maps.hit[0, 0, i]
        assert bool(seen[:, w // 2].all()) and bool((~seen).any() == (float(a[i] + b[i]) < 1))
        torch.testing.assert_close(out[i][seen], expected.expand(h, w)[seen], **tol)


def test_linear_in_the_seed_views(dtype: torch.dtype, tol: dict[str, float]) -> None:
    """The warp is linear in the images (the paper's A = G·C): weights depend on geometry only."""
    h, w = 6, 10
    views = rand(4, 2, 1, h, w, seed=3, dtype=dtype)
    d12 = 2.0 * rand(2, h, w, seed=4) - 1.0
    corr = correspondence_from_disparity(d12.to(dtype))
    warp = NovelViewWarp(12.0)
    kw = dict(correspondence=corr, thetas=[-4.0, 6.0, 15.0])
    combo = warp(2.0 * views[0] - 3.0 * views[2], 2.0 * views[1] - 3.0 * views[3], **kw)
    torch.testing.assert_close(
        combo, 2.0 * warp(views[0], views[1], **kw) - 3.0 * warp(views[2], views[3], **kw), **tol
    )


# --- a tilted camera --------------------------------------------------------------------

ELEVATION = 30.0


def test_tilted_pair_reproduced() -> None:
    """A camera looking down on the cylinder: rows move with depth. The 2D warp gives view 2
    back at theta = alpha, matches the rendering in between, and beats the row-only warp
    when extrapolating; estimate_elevation finds the tilt from the same correspondences."""
    c, tilt = (W - 1) / 2, math.sin(math.radians(ELEVATION))
    view1, view2 = _render(0.0, c, tilt), _render(ALPHA, c, tilt)
    corr = _cylinder_correspondence(ALPHA, c, tilt)
    on = ((torch.arange(W) - c).abs() < R).expand(1, H, W)
    torch.testing.assert_close(
        estimate_elevation(corr, ALPHA, mask=on), torch.tensor([ELEVATION], dtype=torch.float64)
    )
    warp = NovelViewWarp(ALPHA, elevation=ELEVATION)
    out = warp(view1, view2, correspondence=corr, thetas=[0.0, ALPHA])
    torch.testing.assert_close(out[0], view1, atol=1e-12, rtol=0)
    torch.testing.assert_close(out[1], view2, atol=1e-12, rtol=0)
    thetas = [-10.0, 5.0, 10.0, 15.0, 30.0]
    out = warp(view1, view2, correspondence=corr, thetas=thetas)
    _assert_matches_rendering(out, thetas, c, tilt)
    flat = NovelViewWarp(ALPHA)(view1, view2, correspondence=corr, thetas=[-10.0, 30.0])
    inner = _inner(c, rows=3)
    for i, theta in enumerate([-10.0, 30.0]):
        ref = _render(theta, c, tilt)[0]
        err_2d = float((out[-1 if theta > 0 else 0, 0] - ref)[inner].abs().mean())
        err_rows = float((flat[i, 0] - ref)[inner].abs().mean())
        assert err_2d < 0.5 * err_rows, (theta, err_2d, err_rows)


# --- module invariants ------------------------------------------------------------------


def _small_problem(
    b: int, c: int, h: int, w: int, dtype: torch.dtype, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor, Correspondence]:
    view1 = rand(b, c, h, w, seed=20, dtype=dtype, device=device)
    view2 = rand(b, c, h, w, seed=21, dtype=dtype, device=device)
    d12 = 3.0 * rand(b, h, w, seed=22) - 1.5
    return view1, view2, correspondence_from_disparity(d12.to(dtype))


@pytest.mark.parametrize("elevation", [0.0, 25.0])
@pytest.mark.parametrize("two_views", [True, False])
def test_check_module(
    elevation: float, two_views: bool, dtype: torch.dtype, device: torch.device, tol: dict[str, float]
) -> None:
    view1, view2, corr = _small_problem(3, 2, 6, 9, dtype, device)
    warp = NovelViewWarp(12.0, elevation=elevation).to(device)
    inputs = (view1, view2 if two_views else None)
    kwargs = dict(correspondence=corr, thetas=[-5.0, 2.5, 12.0, 20.0])
    check_module(warp, inputs, kwargs, batched_kwargs=("correspondence",), tol=tol)


def test_unbatched_input(dtype: torch.dtype, device: torch.device) -> None:
    view1, view2, corr = _small_problem(1, 3, 5, 7, dtype, device)
    warp = NovelViewWarp(-15.0)
    batched = warp(view1, view2, correspondence=corr, thetas=[-3.0, 4.0])
    single = warp(view1[0], view2[0], correspondence=corr, thetas=[-3.0, 4.0])
    assert single.shape == (2, 3, 5, 7) and single.dtype == dtype and single.device.type == device.type
    torch.testing.assert_close(single, batched[0], atol=0, rtol=0)


def test_correspondence_dtype_does_not_set_output_dtype(dtype: torch.dtype) -> None:
    view1, view2, corr = _small_problem(2, 1, 5, 7, dtype, torch.device("cpu"))
    other = torch.float64 if dtype == torch.float32 else torch.float32
    out = NovelViewWarp(10.0)(view1, view2, correspondence=corr.to(dtype=other), thetas=[4.0])
    assert out.dtype == dtype


def test_gradcheck() -> None:
    view1, view2, corr = _small_problem(1, 1, 5, 6, torch.float64, torch.device("cpu"))
    warp = NovelViewWarp(10.0)
    view1.requires_grad_(True)
    view2.requires_grad_(True)

    def fn(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        return warp(a, b, correspondence=corr, thetas=[3.0, 14.0])

    assert torch.autograd.gradcheck(fn, (view1, view2))
    assert torch.autograd.gradcheck(lambda a: warp(a, correspondence=corr, thetas=[-2.0, 6.0]), (view1,))


# --- errors -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (dict(alpha=0.0), ValueError, r"alpha=0\.0 must not be a multiple of 180"),
        (dict(alpha=-180), ValueError, r"alpha=-180\.0 must not be a multiple of 180"),
        (dict(alpha=math.nan), ValueError, r"alpha=nan must be finite"),
        (dict(alpha="10"), TypeError, r"alpha must be a number of degrees, got str"),
        (
            dict(alpha=10.0, elevation=95.0),
            ValueError,
            r"elevation=95\.0 must be an angle in degrees in \(-90, 90\)",
        ),
        (dict(alpha=10.0, elevation=-90), ValueError, r"elevation=-90 must be an angle"),
        (dict(alpha=10.0, elevation=math.nan), ValueError, r"elevation=nan must be an angle"),
        (dict(alpha=10.0, max_stretch=0), ValueError, r"max_stretch=0 must be positive"),
        (dict(alpha=10.0, max_stretch=-1.0), ValueError, r"max_stretch=-1\.0 must be positive"),
        (dict(alpha=10.0, max_stretch=math.nan), ValueError, r"max_stretch=nan must be positive"),
        (dict(alpha=10.0, depth_sign=2), ValueError, r"depth_sign must be 'auto', 1 or -1, got 2"),
        (dict(alpha=10.0, depth_sign="up"), ValueError, r"depth_sign must be 'auto', 1 or -1, got 'up'"),
        (dict(alpha=10.0, center=math.inf), ValueError, r"center=inf must be a finite column"),
    ],
)
def test_constructor_errors(kwargs: dict, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        NovelViewWarp(**kwargs)


@pytest.mark.parametrize("kwargs", [dict(center="a"), dict(elevation="5"), dict(depth_sign=True)], ids=str)
def test_constructor_type_errors(kwargs: dict) -> None:
    name = next(iter(kwargs))
    with pytest.raises(TypeError, match=name):
        NovelViewWarp(10.0, **kwargs)


def test_view2_dtype_mismatch() -> None:
    view1, view2, corr = _small_problem(1, 1, 5, 7, torch.float64, torch.device("cpu"))
    with pytest.raises(TypeError, match=r"view2 must have the dtype of view1 \(torch.float32\)"):
        NovelViewWarp(10.0)(view1.float(), view2, correspondence=corr, thetas=[4.0])


def test_forward_errors() -> None:
    view1, view2, corr = _small_problem(2, 1, 5, 7, torch.float64, torch.device("cpu"))
    warp = NovelViewWarp(10.0)
    with pytest.raises(ValueError, match=r"thetas must hold at least one angle"):
        warp(view1, view2, correspondence=corr, thetas=[])
    with pytest.raises(ValueError, match=r"thetas must be finite"):
        warp(view1, view2, correspondence=corr, thetas=[1.0, math.nan])
    with pytest.raises(TypeError, match=r"thetas must be a number, a sequence of numbers or a tensor"):
        warp(view1, view2, correspondence=corr, thetas="5")
    with pytest.raises(
        ValueError, match=r"view2 must have the shape of view1 \(2, 1, 5, 7\), got \(2, 1, 5, 6\)"
    ):
        warp(view1, view2[..., :6], correspondence=corr, thetas=[1.0])
    with pytest.raises(TypeError, match=r"view2 must have a floating dtype"):
        warp(view1, view2.long(), correspondence=corr, thetas=[1.0])
    with pytest.raises(
        ValueError, match=r"correspondence must have shape \(B, H, W\) = \(2, 5, 6\).*got \(2, 5, 7\)"
    ):
        warp(view1[..., :6], view2[..., :6], correspondence=corr, thetas=[1.0])
    with pytest.raises(ValueError, match=r"correspondence must have shape \(B, H, W\) = \(1, 5, 7\)"):
        warp(view1[0], view2[0], correspondence=corr, thetas=[1.0])
    with pytest.raises(TypeError, match=r"view1 must have a floating dtype, got torch.int64"):
        warp(view1.long(), correspondence=corr, thetas=[1.0])
    with pytest.raises(TypeError, match=r"view1 must be a torch.Tensor"):
        warp(view1.numpy(), correspondence=corr, thetas=[1.0])
    with pytest.raises(
        ValueError, match=r"view1 must have shape \(B, C, H, W\) or \(C, H, W\), got shape \(5, 7\)"
    ):
        warp(view1[0, 0], correspondence=corr, thetas=[1.0])
    with pytest.raises(ValueError, match=r"n_sources must be 1 or 2, got 3"):
        warp.maps(corr, [1.0], n_sources=3)


def test_repr() -> None:
    text = repr(NovelViewWarp(12.5, 30.0, elevation=10.0, max_stretch=2.0))
    assert text == "NovelViewWarp(alpha=12.5, center=30.0, elevation=10.0, max_stretch=2.0, blend='linear')"


def test_blend_nearest_takes_the_nearer_seed_alone() -> None:
    """``blend="nearest"``: where both seeds see a pixel, seed 1 up to α/2 and seed 2
    beyond (weights 0/1); ``"linear"``: 1 − θ/α and θ/α. One-view pixels are alike."""
    _, _, corr = _small_problem(1, 1, 6, 9, torch.float64, torch.device("cpu"))
    thetas = [-3.0, 2.0, 5.0, 7.0, 13.0]
    near = NovelViewWarp(10.0, blend="nearest").maps(corr, thetas)
    lin = NovelViewWarp(10.0).maps(corr, thetas)
    both = near.hit[0] & near.hit[1]
    want_w1 = torch.tensor([1.0, 1.0, 1.0, 0.0, 0.0], dtype=torch.float64).view(1, -1, 1, 1).expand_as(both)
    assert bool(both.any())
    torch.testing.assert_close(near.weight[0][both], want_w1[both])
    lam = (torch.tensor(thetas, dtype=torch.float64) / 10.0).clamp(0, 1).view(1, -1, 1, 1).expand_as(both)
    torch.testing.assert_close(lin.weight[0][both], (1 - lam)[both])
    one = near.hit[0] ^ near.hit[1]
    torch.testing.assert_close(near.weight[0][one], lin.weight[0][one])
    with pytest.raises(ValueError, match=r"blend must be one of \('linear', 'nearest'\), got 'max'"):
        NovelViewWarp(10.0, blend="max")


def test_forward_with_masks_is_apply_maps_with_masks() -> None:
    view1, view2, corr = _small_problem(2, 2, 6, 9, torch.float64, torch.device("cpu"))
    masks = torch.rand(2, 2, 6, 9, generator=torch.Generator().manual_seed(1)) > 0.3
    warp = NovelViewWarp(10.0)
    out = warp(view1, view2, correspondence=corr, thetas=[-2.0, 4.0], masks=masks)
    ref = warp.apply_maps(warp.maps(corr, [-2.0, 4.0]), torch.stack([view1, view2]), masks)
    torch.testing.assert_close(out, ref)
    v1, v2, c1 = _small_problem(1, 2, 6, 9, torch.float64, torch.device("cpu"))
    single = warp(v1[0], v2[0], correspondence=c1, thetas=[4.0], masks=masks[:, 0])
    batched = warp(v1, v2, correspondence=c1, thetas=[4.0], masks=masks[:, :1])
    torch.testing.assert_close(single, batched[0])
    with pytest.raises(
        ValueError, match=r"masks must have shape \(2, 2, 6, 9\) \(S, \[B,\] H, W\), got \(2, 6, 9\)"
    ):
        warp(view1, view2, correspondence=corr, thetas=[4.0], masks=masks[:, 0])
    with pytest.raises(TypeError, match="masks must be a tensor, got list"):
        warp(view1, view2, correspondence=corr, thetas=[4.0], masks=[1])


def test_thetas_beyond_a_quarter_turn_are_refused() -> None:
    view1, view2, corr = _small_problem(1, 1, 5, 7, torch.float64, torch.device("cpu"))
    with pytest.raises(ValueError, match=r"thetas must lie within \(-90, 90\)"):
        NovelViewWarp(10.0)(view1, view2, correspondence=corr, thetas=[10.0, 95.0])
