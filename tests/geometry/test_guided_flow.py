"""The guided flow (row matcher + TV-L1): rendered views with exact correspondences at small
and large angles, against TV-L1 alone, batching, small views, dtype, device and bad input."""

from __future__ import annotations

import dataclasses

import pytest
import torch
import torch.nn.functional as F

from torch_eigview.datasets.cameras import OrthographicCamera
from torch_eigview.datasets.correspondence import exact_correspondence, view_correspondence
from torch_eigview.datasets.renderer import render_views
from torch_eigview.datasets.shapes import SHAPES, make_object
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.guided_flow import MIN_SIDE, guided_tvl1, prior_reduction
from torch_eigview.synthesis import SynthesisOptions, object_geometries, pair_geometry, synthesize_views

SIZE = 48
FAST = {"num_warp": 3, "num_iter": 5}  # SynthesisOptions' TV-L1 preset


def _pair(name: str, alpha: float) -> tuple[torch.Tensor, torch.Tensor, Correspondence]:
    """Rendered views (2, 1, SIZE, SIZE) at 0 and alpha, the pixels of view 1 that view 2
    sees, and the exact correspondences."""
    obj, cam = make_object(name), OrthographicCamera(SIZE)
    views = render_views(obj, [0.0, alpha], cam)
    return views, view_correspondence(obj, 0.0, alpha, cam).visible, exact_correspondence(obj, alpha, cam)


def _interior(mask: torch.Tensor, margin: int = 2) -> torch.Tensor:
    """``mask`` (H, W) eroded by ``margin`` pixels: away from silhouettes and occlusions."""
    k = 2 * margin + 1
    return -F.max_pool2d(-mask[None, None].float(), k, 1, margin)[0, 0] > 0.5


def _median_error(corr: Correspondence, exact: Correspondence, inner: torch.Tensor) -> float:
    return float((corr.disparity_12[0] - exact.disparity_12[0])[inner].abs().median())


@pytest.mark.parametrize("name", SHAPES)
def test_matches_exact_disparity_at_small_angle(name: str) -> None:
    """α = 10°, where TV-L1 alone follows the motion: the guided flow is as close to exact."""
    views, seen, exact = _pair(name, 10.0)
    corr = guided_tvl1(views[:1], views[1:], 10.0, **FAST)
    assert isinstance(corr, Correspondence) and corr.shape == (1, SIZE, SIZE)
    inner = _interior(seen)
    assert _median_error(corr, exact, inner) < 0.3, name
    assert float(corr.valid_12[0][inner].float().mean()) > 0.9, name


@pytest.mark.parametrize("alpha", [30.0, 45.0])
def test_follows_large_angles_where_tvl1_does_not(alpha: float) -> None:
    """Far apart in angle the disparity outgrows TV-L1's coarse-to-fine reach; the row
    matcher's prior brings it back within it (both directions)."""
    views, seen, exact = _pair("head", alpha)
    inner = _interior(seen)
    guided = guided_tvl1(views[:1], views[1:], alpha, **FAST)
    alone = estimate_correspondence(views[:1], views[1:], **FAST)
    err_guided, err_alone = _median_error(guided, exact, inner), _median_error(alone, exact, inner)
    assert err_guided < 1.0 and err_guided < 0.25 * err_alone, (err_guided, err_alone)
    inner_21 = _interior(exact.valid_21[0])
    err_21 = (guided.disparity_21[0] - exact.disparity_21[0])[inner_21].abs().median()
    assert float(err_21) < 1.0, err_21


def test_batched_equals_pair_by_pair_dtype_device(device: torch.device) -> None:
    a, _, _ = _pair("egg", 20.0)
    b, _, _ = _pair("cylinder", 20.0)
    v1, v2 = torch.cat([a[:1], b[:1]]).to(device), torch.cat([a[1:], b[1:]]).to(device)
    both = guided_tvl1(v1, v2, 20.0, **FAST)
    for i in range(2):
        one = guided_tvl1(v1[i : i + 1], v2[i : i + 1], 20.0, **FAST)
        for f in dataclasses.fields(Correspondence):
            torch.testing.assert_close(
                getattr(one, f.name), getattr(both, f.name)[i : i + 1], atol=1e-4, rtol=0
            )
    double = guided_tvl1(v1.double(), v2.double(), 20.0, elevation=0.0, **FAST)
    assert double.disparity_12.dtype == torch.float64 and double.disparity_12.device.type == device.type
    assert double.valid_12.dtype == torch.bool
    assert double.vertical_12 is not None and double.vertical_12.dtype == torch.float64


def test_dispatch_and_geometry_batches(monkeypatch: pytest.MonkeyPatch) -> None:
    """estimate_correspondence and pair_geometry reach it with ``method="guided"`` (the
    default); pairs and objects of one angle go through one call per angle, each equal to
    its pair alone, every object in order."""
    import torch_eigview.synthesis.seed_pairs as seed_pairs

    views, _, _ = _pair("superquadric", 45.0)
    via = estimate_correspondence(views[:1], views[1:], method="guided", alpha=45.0, elevation=0.0, **FAST)
    torch.testing.assert_close(
        via.disparity_12, guided_tvl1(views[:1], views[1:], 45.0, elevation=0.0, **FAST).disparity_12
    )
    opts = SynthesisOptions(elevation=0.0)
    assert opts.flow == "guided"
    torch.testing.assert_close(
        pair_geometry(views, 45.0, opts)[0].correspondence.disparity_12, via.disparity_12
    )
    # Seeds at 0, 20, 30, 50 (Sec. 4.1's per-pair angles 20, 10, 20): two calls, one per angle,
    # for two objects at once.
    cam = OrthographicCamera(SIZE)
    poses = [0.0, 20.0, 30.0, 50.0]
    objects = [render_views(make_object(name), poses, cam) for name in ("head", "egg")]
    calls: list[int] = []
    real = seed_pairs.estimate_correspondence

    def counted(*args: object, **kwargs: object) -> Correspondence:
        calls.append(len(args[0]))  # type: ignore[arg-type]
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(seed_pairs, "estimate_correspondence", counted)
    many = object_geometries(objects, [20.0, 10.0, 20.0], opts)
    assert sorted(calls) == [2, 4]  # the 10° pair of both objects, the two 20° pairs of both
    for seeds, geo in zip(objects, many, strict=True):
        for n, step in enumerate([20.0, 10.0, 20.0]):
            alone = guided_tvl1(seeds[n : n + 1], seeds[n + 1 : n + 2], step, elevation=0.0, **FAST)
            torch.testing.assert_close(
                geo[n].correspondence.disparity_12, alone.disparity_12, atol=1e-4, rtol=0
            )


def test_small_views_are_tvl1_alone() -> None:
    """Below the row matcher's smallest side there is no prior: TV-L1 alone, in float64 too."""
    gen = torch.Generator().manual_seed(0)
    v1, v2 = torch.rand(2, 1, 1, MIN_SIDE - 1, 5, generator=gen)
    for dtype in (torch.float32, torch.float64):
        guided = guided_tvl1(v1.to(dtype), v2.to(dtype), 10.0, **FAST)
        alone = estimate_correspondence(v1.to(dtype), v2.to(dtype), **FAST)
        assert guided.disparity_12.dtype == dtype
        torch.testing.assert_close(guided.disparity_12, alone.disparity_12, atol=1e-5, rtol=0)
        torch.testing.assert_close(guided.disparity_21, alone.disparity_21, atol=1e-5, rtol=0)
    # One-pixel-high views go through estimate_correspondence's one-row path: TV-L1 along the row.
    row = estimate_correspondence(v1[:, :, :1], v2[:, :, :1], method="guided", alpha=10.0, **FAST)
    one = estimate_correspondence(v1[:, :, :1], v2[:, :, :1], **FAST)
    torch.testing.assert_close(row.disparity_12, one.disparity_12, atol=1e-5, rtol=0)


def test_empty_batch_3d_views_and_gradients() -> None:
    views, _, _ = _pair("egg", 20.0)
    empty = guided_tvl1(views[:0], views[:0], 20.0)
    assert empty.shape == (0, SIZE, SIZE) and empty.valid_12.dtype == torch.bool
    flat = guided_tvl1(views[0], views[1], 20.0, **FAST)  # (C, H, W) each
    torch.testing.assert_close(
        flat.disparity_12, guided_tvl1(views[:1], views[1:], 20.0, **FAST).disparity_12
    )
    # Views that require grad enter detached (the matches are not differentiable), and the
    # synthesis with the default flow still differentiates through the warp.
    seeds = views.clone().requires_grad_()
    corr = guided_tvl1(seeds[:1], seeds[1:], 20.0, **FAST)
    assert not corr.disparity_12.requires_grad
    out = synthesize_views(seeds, 20.0, [5.0], SynthesisOptions(elevation=0.0, extent=False)).views
    out.sum().backward()
    assert seeds.grad is not None and float(seeds.grad.abs().sum()) > 0


def test_large_views_take_the_prior_at_a_reduced_size() -> None:
    """A view larger than ``prior_side`` has its prior matched on a view reduced by a power
    of two and scaled back; TV-L1 takes up the difference (here ``prior_side=24`` on the
    48-pixel views, a reduction by 2)."""
    views, seen, exact = _pair("head", 45.0)
    inner = _interior(seen)
    full = guided_tvl1(views[:1], views[1:], 45.0, **FAST)
    assert prior_reduction(48, 48) == 1 and prior_reduction(48, 48, 24) == 2
    reduced = guided_tvl1(views[:1], views[1:], 45.0, prior_side=24, **FAST)
    err_full, err_reduced = _median_error(full, exact, inner), _median_error(reduced, exact, inner)
    assert err_reduced < 1.0 and err_reduced < 2 * err_full + 0.2, (err_reduced, err_full)
    assert not torch.equal(full.disparity_12, reduced.disparity_12)


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (
            lambda v: guided_tvl1(v, v, 10.0, warps=3),
            ValueError,
            r"options \['warps'\] are neither the row matcher's",
        ),
        (lambda v: guided_tvl1(v, v, 0.0), ValueError, r"alpha"),
        (lambda v: guided_tvl1(v[..., :3, :3], v[..., :3, :3], 180.0), ValueError, r"alpha=180"),
        (lambda v: guided_tvl1(v, v, 10.0, num_warp=0), ValueError, r"num_warp"),
        (lambda v: guided_tvl1(v, v, 10.0, patch=4), ValueError, r"patch=4 must be odd"),
        (lambda v: guided_tvl1(v, v, 10.0, prior_side=0), ValueError, r"prior_side=0 must be >= 1"),
        (lambda v: guided_tvl1(v, v, 10.0, prior_side=64.0), TypeError, r"prior_side must be an integer"),
        (lambda v: estimate_correspondence(v, v, method="guided"), ValueError, r"pass alpha"),
        (lambda v: guided_tvl1(v[..., :3, :3], v[..., :3, :3], 10.0, depth=-1.0), ValueError, r"depth=-1.0"),
        (lambda v: guided_tvl1(v[..., :3, :3], v[..., :3, :3], 10.0, center="a"), TypeError, r"center"),
        (lambda v: guided_tvl1(v[0, 0], v[0, 0], 10.0), ValueError, r"view1 must have shape \(C, H, W\)"),
        (lambda v: guided_tvl1([v], v, 10.0), TypeError, r"view1"),
        (lambda v: guided_tvl1(v, v[..., :6], 10.0), ValueError, r"view2 must have the shape of view1"),
        (lambda v: guided_tvl1(v * float("nan"), v, 10.0), ValueError, r"view1"),
        (lambda v: guided_tvl1(v * 1e30, v, 10.0), ValueError, r"magnitude"),
        (
            lambda v: SynthesisOptions(flow_options={"alpha": 99.0}),
            ValueError,
            r"flow_options must not hold \['alpha'\]",
        ),
    ],
    ids=[
        "unknown-option",
        "alpha-0",
        "alpha-180-small",
        "tvl1-option",
        "row-option",
        "prior-side-0",
        "prior-side-float",
        "no-alpha",
        "row-option-small",
        "center-small",
        "2d",
        "list",
        "shapes",
        "nan",
        "huge",
        "flow-options-alpha",
    ],
)
def test_bad_arguments(call: object, error: type[Exception], match: str) -> None:
    view = torch.rand(1, 1, 8, 8, generator=torch.Generator().manual_seed(1))
    with pytest.raises(error, match=match):
        call(view)  # type: ignore[operator]
