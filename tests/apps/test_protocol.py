"""Tests for the shared recognition protocol: gallery, projection, recognizer, scoring."""

from __future__ import annotations

import math

import pytest
import torch

from torch_eigview.apps.protocol import build_recognizer, fit_projection, score, stack_gallery
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection


def _views(n: int, seed: int) -> torch.Tensor:
    return torch.rand(n, 1, 6, 5, generator=torch.Generator().manual_seed(seed))


def test_stack_gallery_keeps_the_order_of_the_blocks() -> None:
    a, b = _views(2, 0), _views(3, 1)
    x, labels, poses = stack_gallery([(a, 7, [0.0, 5.0]), (b, 3, [-5.0, 0.0, 5.0])])
    torch.testing.assert_close(x, torch.cat([a, b]), atol=0, rtol=0)
    assert labels.tolist() == [7, 7, 3, 3, 3] and labels.dtype == torch.int64
    assert poses.tolist() == [0.0, 5.0, -5.0, 0.0, 5.0] and poses.dtype == x.dtype


def test_stack_gallery_takes_the_views_dtype() -> None:
    _, _, poses = stack_gallery([(_views(2, 0).double(), 0, [0.0, 1.0])])
    assert poses.dtype == torch.float64


@pytest.mark.parametrize("unit_norm", [True, False])
def test_fit_projection_is_the_eigenspace_of_the_gallery(unit_norm: bool) -> None:
    x = _views(12, 2)
    projection = fit_projection(x, 4, unit_norm=unit_norm)
    assert isinstance(projection, EigenProjection)
    space = Eigenspace(4).fit(unit_rows(x) if unit_norm else x.flatten(1))
    torch.testing.assert_close(projection.components, space.components_, atol=0, rtol=0)
    assert projection.image_shape == (1, 6, 5)
    want = (unit_rows(x) if unit_norm else x.flatten(1)) - space.mean_
    torch.testing.assert_close(projection(x), want @ space.components_.T)


def test_fit_projection_with_a_kernel() -> None:
    projection = fit_projection(_views(12, 3), 3, kernel="rbf", gamma="median")
    assert isinstance(projection, KernelProjection)


def test_build_recognizer_finds_every_gallery_view() -> None:
    x, labels, poses = stack_gallery([(_views(4, 4), 0, [0.0, 1.0, 2.0, 3.0]), (_views(4, 5), 1, [0.0] * 4)])
    rec = build_recognizer(x, labels, poses, 7, label_names=["a", "b"])
    assert rec.label_names == ["a", "b"]
    result = rec.predict(x)
    assert result.labels.tolist() == labels.tolist()
    assert result.poses.tolist() == poses.tolist()


def test_score_counts_and_pose_errors() -> None:
    x, labels, poses = stack_gallery(
        [(_views(3, 6), 0, [170.0, 175.0, 180.0]), (_views(3, 7), 1, [0.0, 5.0, 10.0])]
    )
    rec = build_recognizer(x, labels, poses, 5)
    truth_0 = torch.tensor([-170.0, 175.0, 180.0])  # the first one 20 degrees off, or 340 unwrapped
    tests = [("first", 0, x[:3], truth_0), ("second", 1, x[[0, 4, 5]], torch.tensor([0.0, 5.0, 10.0]))]
    wrapped = score(rec, tests, wrap=True)
    assert wrapped.n_test == 6
    assert wrapped.per_object == {"first": 100.0, "second": pytest.approx(200.0 / 3)}
    assert wrapped.accuracy == pytest.approx(500.0 / 6)
    assert wrapped.pose_mae_deg == pytest.approx(20.0 / 5)
    assert score(rec, tests).pose_mae_deg == pytest.approx(340.0 / 5)


def test_score_without_a_correct_view_has_no_pose_error() -> None:
    x, labels, poses = stack_gallery([(_views(2, 8), 0, [0.0, 1.0]), (_views(2, 9), 1, [0.0, 1.0])])
    rec = build_recognizer(x, labels, poses, 3)
    result = score(rec, [("wrong", 1, x[:2], poses[:2])])
    assert result.accuracy == 0.0 and result.per_object == {"wrong": 0.0}
    assert math.isnan(result.pose_mae_deg)
