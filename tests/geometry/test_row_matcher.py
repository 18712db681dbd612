"""Semi-global matching along rows: rendered views with exact correspondences, occlusions,
the dispatch from estimate_correspondence, dtype, device and bad input."""

from __future__ import annotations

import dataclasses

import pytest
import torch
import torch.nn.functional as F

from torch_eigview.datasets.cameras import OrthographicCamera
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.datasets.correspondence import exact_correspondence, view_correspondence
from torch_eigview.datasets.renderer import render_views
from torch_eigview.datasets.shapes import SHAPES, make_object
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.row_matcher import match_rows
from torch_eigview.synthesis import SynthesisOptions, pair_geometry

SIZE = 48


def _pair(name: str, alpha: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Rendered views (2, 1, SIZE, SIZE) at 0 and alpha, and the object's mask of view 1 seen in view 2."""
    obj, cam = make_object(name), OrthographicCamera(SIZE)
    views = render_views(obj, [0.0, alpha], cam)
    return views, view_correspondence(obj, 0.0, alpha, cam).visible


def _interior(mask: torch.Tensor, margin: int = 2) -> torch.Tensor:
    """``mask`` (H, W) eroded by ``margin`` pixels: away from silhouettes and occlusions."""
    k = 2 * margin + 1
    return -F.max_pool2d(-mask[None, None].float(), k, 1, margin)[0, 0] > 0.5


@pytest.mark.parametrize("name", SHAPES)
def test_matches_exact_disparity(name: str) -> None:
    """Against the renderer's exact correspondences, both directions, α = 10°."""
    alpha = 10.0
    views, seen = _pair(name, alpha)
    exact = exact_correspondence(make_object(name), alpha, OrthographicCamera(SIZE))
    corr = match_rows(views[:1], views[1:], alpha)
    assert isinstance(corr, Correspondence) and corr.shape == (1, SIZE, SIZE)
    inner = _interior(seen)
    err = (corr.disparity_12[0] - exact.disparity_12[0])[inner].abs()
    assert float(err.median()) < 0.3 and float(err.quantile(0.9)) < 0.6, (
        name,
        err.median(),
        err.quantile(0.9),
    )
    assert float(corr.valid_12[0][inner].float().mean()) > 0.95
    inner_21 = _interior(exact.valid_21[0])
    err_21 = (corr.disparity_21[0] - exact.disparity_21[0])[inner_21].abs()
    assert float(err_21.median()) < 0.3, (name, err_21.median())


def test_left_right_check_flags_occlusions() -> None:
    """At α = 30° the head hides part of itself: most pixels of view 1 that view 2 does not
    see fail the left–right check, while most of those it sees pass."""
    alpha = 30.0
    views, seen = _pair("head", alpha)
    mask = views[0, 0] > 0
    occluded = mask & ~seen
    assert int(occluded.sum()) > 50
    corr = match_rows(views[:1], views[1:], alpha)
    flagged = ~corr.valid_12[0]
    assert float(flagged[occluded].float().mean()) > 0.8
    assert float(flagged[_interior(seen)].float().mean()) < 0.35


def test_beats_tvl1_at_large_angle() -> None:
    """At α = 30° the disparity outgrows TV-L1's coarse-to-fine reach on the head."""
    alpha = 30.0
    views, seen = _pair("head", alpha)
    exact = exact_correspondence(make_object("head"), alpha, OrthographicCamera(SIZE))
    inner = _interior(seen)
    rows = match_rows(views[:1], views[1:], alpha)
    flow = estimate_correspondence(views[:1], views[1:], num_warp=3, num_iter=5)
    err_rows = (rows.disparity_12[0] - exact.disparity_12[0])[inner].abs().median()
    err_flow = (flow.disparity_12[0] - exact.disparity_12[0])[inner].abs().median()
    assert float(err_rows) < 0.5 * float(err_flow), (err_rows, err_flow)


def test_batched_equals_unbatched_and_dtype(device: torch.device) -> None:
    """Batched pairs equal one pair at a time; the output follows the input's dtype and device."""
    a, _ = _pair("egg", 10.0)
    b, _ = _pair("cylinder", 10.0)
    v1 = torch.cat([a[:1], b[:1]]).to(device)
    v2 = torch.cat([a[1:], b[1:]]).to(device)
    both = match_rows(v1, v2, 10.0)
    for i in range(2):
        one = match_rows(v1[i], v2[i], 10.0)
        for f in dataclasses.fields(Correspondence):
            torch.testing.assert_close(
                getattr(one, f.name), getattr(both, f.name)[i : i + 1], atol=1e-4, rtol=0
            )
    double = match_rows(v1.double(), v2.double(), 10.0, elevation=0.0)
    assert double.disparity_12.dtype == torch.float64 and double.disparity_12.device.type == device.type
    assert double.valid_12.dtype == torch.bool
    assert double.vertical_12 is not None and double.vertical_12.dtype == torch.float64


def test_given_elevation_and_dispatch() -> None:
    """``elevation=0`` on an untilted camera gives matches as good as ``"auto"``;
    estimate_correspondence and pair_geometry reach the matcher with ``method="rows"``."""
    alpha = 10.0
    views, seen = _pair("head", alpha)
    exact = exact_correspondence(make_object("head"), alpha, OrthographicCamera(SIZE))
    inner = _interior(seen)
    level = match_rows(views[:1], views[1:], alpha, elevation=0.0)
    err = (level.disparity_12[0] - exact.disparity_12[0])[inner].abs()
    assert float(err.median()) < 0.3
    via = estimate_correspondence(views[:1], views[1:], method="rows", alpha=alpha)
    torch.testing.assert_close(via.disparity_12, match_rows(views[:1], views[1:], alpha).disparity_12)
    # A given elevation is the matcher's too.
    geo = pair_geometry(views, alpha, SynthesisOptions(flow="rows", elevation=0.0))
    torch.testing.assert_close(geo[0].correspondence.disparity_12, level.disparity_12)
    auto = pair_geometry(views, alpha, SynthesisOptions(flow="rows"))
    torch.testing.assert_close(auto[0].correspondence.disparity_12, via.disparity_12)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (dict(alpha=0.0), ValueError, r"alpha"),
        (dict(cost="sad"), ValueError, r"cost='sad' must be one of"),
        (dict(patch=4), ValueError, r"patch=4 must be odd"),
        (dict(p1=0.0), ValueError, r"p1=0.0 must be positive"),
        (dict(depth=-1.0), ValueError, r"depth=-1.0 must be positive"),
        (dict(elevation="up"), ValueError, r"elevation must be a number of degrees or 'auto'"),
        (dict(center="x"), TypeError, r"center must be a number"),
    ],
    ids=str,
)
def test_bad_arguments(kwargs: dict[str, object], error: type[Exception], match: str) -> None:
    view = torch.rand(1, 8, 8)
    args: dict[str, object] = {"alpha": 10.0, **kwargs}
    with pytest.raises(error, match=match):
        match_rows(view, view, **args)  # type: ignore[arg-type]


def test_bad_views() -> None:
    with pytest.raises(ValueError, match=r"view2 must have the shape of view1"):
        match_rows(torch.rand(1, 8, 8), torch.rand(1, 8, 9), 10.0)
    with pytest.raises(TypeError, match=r"view1"):
        match_rows(torch.ones(1, 8, 8, dtype=torch.long), torch.ones(1, 8, 8, dtype=torch.long), 10.0)
    with pytest.raises(ValueError, match=r"view1"):
        match_rows(torch.full((1, 8, 8), float("nan")), torch.rand(1, 8, 8), 10.0)


@pytest.mark.parametrize("obj", [5, 14])
def test_same_result_every_run(folder: CoilFolder, obj: int) -> None:
    """Run after run on the same views the matches are equal bit for bit (the line model's
    float32 least squares in BLAS used to vary in its last bits with the buffers' alignment,
    and the labels with it: COIL's objects 5 and 14 at 90 and 100 degrees changed in
    1,400-5,300 pixels from one call to the next)."""
    views = folder.images(obj, [90.0, 100.0])
    first = match_rows(views[:1], views[1:], 10.0)
    for _ in range(5):
        again = match_rows(views[:1], views[1:], 10.0)
        for field in dataclasses.fields(first):
            a, b = getattr(first, field.name), getattr(again, field.name)
            assert torch.equal(a, b), field.name


def test_empty_batch_and_views_that_require_grad() -> None:
    """B = 0 gives an empty correspondence; views that require grad enter detached (the
    aggregation writes in place, the matches are not differentiable)."""
    views, _ = _pair("egg", 10.0)
    empty = match_rows(views[:0], views[:0], 10.0)
    assert empty.shape == (0, SIZE, SIZE) and empty.valid_12.dtype == torch.bool
    seeds = views.clone().requires_grad_()
    corr = match_rows(seeds[:1], seeds[1:], 10.0)
    torch.testing.assert_close(corr.disparity_12, match_rows(views[:1], views[1:], 10.0).disparity_12)
    assert not corr.disparity_12.requires_grad


@pytest.mark.parametrize("chunk", [1, 40_000, 1 << 30])
def test_cost_volume_in_label_chunks_is_the_same(monkeypatch: pytest.MonkeyPatch, chunk: int) -> None:
    """The cost volume is computed a few labels at a time (in cache on the CPU): one label
    per chunk, a few, or all at once give the same matches bit for bit as the default
    slicing, with the elevation searched (the line model's quarter-resolution volume is
    chunked too)."""
    import torch_eigview._tuning as _tuning

    views, _ = _pair("head", 30.0)
    reference = match_rows(views[:1], views[1:], 30.0)
    monkeypatch.setattr(_tuning, "COST_CHUNK_CPU", chunk)
    chunked = match_rows(views[:1], views[1:], 30.0)
    for name in ("disparity_12", "disparity_21", "vertical_12", "vertical_21", "valid_12", "valid_21"):
        assert torch.equal(getattr(chunked, name), getattr(reference, name)), name
