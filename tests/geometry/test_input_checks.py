"""Edge cases at the geometry boundary: tiny, empty and batch-0 views, thresholds, masks,
a missing correspondence, diverging flow, and the elevation fit's inputs."""

from __future__ import annotations

import math
import re

import pytest
import torch

from torch_eigview.geometry.correspondence import (
    Correspondence,
    check_correspondence,
    correspondence_from_disparity,
)
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.pose import estimate_elevation, orthographic_coefficients
from torch_eigview.warp.novel_view import NovelViewWarp

from tests.helpers import rand


@pytest.mark.parametrize("shape", [(1, 0, 16), (1, 8, 1), (1, 1, 1)], ids=["empty", "Hx1", "1x1"])
def test_too_small_views(shape: tuple[int, ...]) -> None:
    v = torch.zeros(shape)
    with pytest.raises(ValueError, match=r"view1 must be at least 2x2 pixels"):
        estimate_correspondence(v, v)


def test_one_row_views_match_along_their_row() -> None:
    """A 1-pixel-high pair is matched as its row twice over: the same as a 2-row pair's top row."""
    row = torch.exp(-0.5 * ((torch.arange(24.0, dtype=torch.float64) - 10.0) / 2.0) ** 2).view(1, 1, 24)
    moved = torch.roll(row, 2, dims=-1)
    corr = estimate_correspondence(row, moved)
    two = estimate_correspondence(row.expand(1, 2, 24), moved.expand(1, 2, 24))
    assert corr.shape == (1, 1, 24)
    for name in ("disparity_12", "disparity_21", "valid_12", "valid_21", "vertical_12", "vertical_21"):
        assert torch.equal(getattr(corr, name), getattr(two, name)[:, :1]), name
    assert (corr.disparity_12[0, 0, 8:13] - 2.0).abs().max() < 0.5  # the bump moved 2 pixels right
    # ILK's per-pixel 2x2 system is singular without a vertical gradient: refused, not a zero flow.
    with pytest.raises(ValueError, match=r"one pixel high \(H=1, W=24\): method='ilk' needs 2 rows"):
        estimate_correspondence(row, moved, method="ilk")


def test_batch_zero_gives_an_empty_correspondence() -> None:
    v = torch.zeros(0, 1, 6, 7)
    corr = estimate_correspondence(v, v)
    assert corr.shape == (0, 6, 7) and corr.valid_12.dtype == torch.bool


@pytest.mark.parametrize("threshold", [-1.0, 0.0, math.nan, math.inf])
def test_threshold(threshold: float) -> None:
    v = rand(1, 6, 7)
    with pytest.raises(ValueError, match=f"threshold={threshold!r} must be positive"):
        estimate_correspondence(v, v, threshold=threshold)
    with pytest.raises(ValueError, match="threshold="):
        correspondence_from_disparity(torch.zeros(6, 7), threshold=threshold)


def test_flow_on_huge_values_names_the_views() -> None:
    v1, v2 = rand(1, 8, 16, seed=1) * 1e30, rand(1, 8, 16, seed=2) * 1e30
    with pytest.raises(
        ValueError, match=r"tvl1-skimage flow between view1 and view2 diverged.*largest magnitude 1e\+30"
    ):
        estimate_correspondence(v1, v2, method="tvl1-skimage")
    # The torch TV-L1 would not diverge: its data term would vanish, and the flow be 0.
    with pytest.raises(
        ValueError, match=r"tvl1 flow between view1 and view2 cannot take values of magnitude 1e\+30"
    ):
        estimate_correspondence(v1, v2)


def test_masks_of_the_wrong_size() -> None:
    with pytest.raises(ValueError, match=r"valid_12 must have shape \(1, 8, 16\), got \(3, 3\)"):
        correspondence_from_disparity(torch.zeros(8, 16), valid_12=torch.ones(3, 3, dtype=torch.bool))
    with pytest.raises(TypeError, match="valid_21 must be a bool tensor"):
        correspondence_from_disparity(torch.zeros(8, 16), valid_21=[[True]])  # type: ignore[arg-type]
    ok = correspondence_from_disparity(torch.zeros(8, 16), valid_12=torch.ones(8, 16, dtype=torch.bool))
    assert bool(ok.valid_12.all())


def test_check_correspondence() -> None:
    with pytest.raises(TypeError, match=r"correspondence must be a Correspondence .* got NoneType"):
        check_correspondence(None)
    d = torch.zeros(1, 4, 5)
    bad = Correspondence(d, d, torch.ones(1, 4, 4, dtype=torch.bool), torch.ones(1, 4, 5, dtype=torch.bool))
    with pytest.raises(ValueError, match=r"correspondence.valid_12 must have the shape of disparity_12"):
        check_correspondence(bad)
    with pytest.raises(TypeError, match="correspondence must be a Correspondence"):
        NovelViewWarp(10.0).maps(None, [5.0])  # type: ignore[arg-type]


def test_estimate_elevation_inputs() -> None:
    corr = estimate_correspondence(rand(1, 8, 9, seed=1), rand(1, 8, 9, seed=2))
    with pytest.raises(TypeError, match="correspondence must be a Correspondence"):
        estimate_elevation(None, 10.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"mask must be a tensor of shape \(1, 8, 9\)"):
        estimate_elevation(corr, 10.0, mask=torch.ones(8, 8, dtype=torch.bool))
    with pytest.raises(ValueError, match="center=nan must be finite"):
        estimate_elevation(corr, 10.0, center=math.nan)


@pytest.mark.parametrize("alpha", [1e300, -400.0, 361.0])
def test_alpha_beyond_a_turn(alpha: float) -> None:
    with pytest.raises(
        ValueError, match=re.escape(f"alpha={alpha} must be an angle between seed views in [-360, 360]")
    ):
        orthographic_coefficients([0.0], alpha)
