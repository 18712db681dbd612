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
from torch_eigview.geometry.guided_flow import MIN_SIDE, guided_tvl1
from torch_eigview.synthesis import SynthesisOptions, object_geometries, pair_geometry

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


def test_dispatch_and_geometry_batches() -> None:
    """estimate_correspondence and pair_geometry reach it with ``method="guided"`` (the
    default); pairs and objects of one angle go through one call, equal to one at a time."""
    views, _, _ = _pair("superquadric", 45.0)
    via = estimate_correspondence(views[:1], views[1:], method="guided", alpha=45.0, **FAST)
    torch.testing.assert_close(via.disparity_12, guided_tvl1(views[:1], views[1:], 45.0, **FAST).disparity_12)
    opts = SynthesisOptions(elevation=0.0)
    assert opts.flow == "guided"
    torch.testing.assert_close(
        pair_geometry(views, 45.0, opts)[0].correspondence.disparity_12, via.disparity_12
    )
    # Three seeds 45° apart: both pairs in one call, and two objects in one call.
    obj, cam = make_object("head"), OrthographicCamera(SIZE)
    three = render_views(obj, [0.0, 45.0, 90.0], cam)
    geo = pair_geometry(three, 45.0, opts)
    for n in range(2):
        alone = guided_tvl1(three[n : n + 1], three[n + 1 : n + 2], 45.0, **FAST)
        torch.testing.assert_close(geo[n].correspondence.disparity_12, alone.disparity_12)
    many = object_geometries([three, three.flip(-1)], 45.0, opts)
    for n in range(2):
        torch.testing.assert_close(many[0][n].correspondence.disparity_12, geo[n].correspondence.disparity_12)


def test_small_views_are_tvl1_alone() -> None:
    """Below the row matcher's smallest side there is no prior: TV-L1 alone."""
    gen = torch.Generator().manual_seed(0)
    v1, v2 = torch.rand(2, 1, 1, MIN_SIDE - 1, 5, generator=gen)
    guided = guided_tvl1(v1, v2, 10.0, **FAST)
    alone = estimate_correspondence(v1, v2, **FAST)
    torch.testing.assert_close(guided.disparity_12, alone.disparity_12, atol=1e-5, rtol=0)
    torch.testing.assert_close(guided.disparity_21, alone.disparity_21, atol=1e-5, rtol=0)
    # One-pixel-high views go through estimate_correspondence's one-row path.
    row = estimate_correspondence(v1[:, :, :1], v2[:, :, :1], method="guided", alpha=10.0)
    assert row.shape == (1, 1, 5)


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda v: guided_tvl1(v, v, 10.0, warps=3), ValueError, r"flow options \['warps'\] .* row matcher"),
        (lambda v: guided_tvl1(v, v, 0.0), ValueError, r"alpha"),
        (lambda v: guided_tvl1(v[..., :3, :3], v[..., :3, :3], 180.0), ValueError, r"alpha=180"),
        (lambda v: guided_tvl1(v, v, 10.0, num_warp=0), ValueError, r"num_warp"),
        (lambda v: guided_tvl1(v, v, 10.0, patch=4), ValueError, r"patch=4 must be odd"),
        (lambda v: estimate_correspondence(v, v, method="guided"), ValueError, r"pass alpha"),
    ],
    ids=["unknown-option", "alpha-0", "alpha-180-small", "tvl1-option", "row-option", "no-alpha"],
)
def test_bad_arguments(call: object, error: type[Exception], match: str) -> None:
    view = torch.rand(1, 1, 8, 8, generator=torch.Generator().manual_seed(1))
    with pytest.raises(error, match=match):
        call(view)  # type: ignore[operator]
