"""Tests for ``score``: the recognition of each object's test views, its accuracy and pose error."""

from __future__ import annotations

import math
import threading

import pytest
import torch

from torch_eigview.evaluation import score
from torch_eigview.method import FewViewEigenspace
from torch_eigview.nn.recognition import NearestNeighborRecognizer


def _views(n: int, seed: int) -> torch.Tensor:
    return torch.rand(n, 1, 6, 5, generator=torch.Generator().manual_seed(seed))


def _gallery(
    blocks: list[tuple[torch.Tensor, int, list[float]]],
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The blocks' views, labels and poses, stacked as the gallery holds them."""
    x = torch.cat([views for views, _, _ in blocks])
    labels = torch.tensor([label for _, label, angles in blocks for _ in angles])
    poses = torch.tensor([a for _, _, angles in blocks for a in angles], dtype=x.dtype)
    return x, labels, poses


def _recognizer(blocks: list[tuple[torch.Tensor, int, list[float]]], k: int) -> NearestNeighborRecognizer:
    """The recognizer over the blocks' views themselves (no synthesis), as the pipeline builds it."""
    est = FewViewEigenspace(k, synth=None).fit(
        [views for views, _, _ in blocks],
        [angles for _, _, angles in blocks],
        labels=[label for _, label, _ in blocks],
    )
    return est.recognizer_


def test_score_counts_and_pose_errors() -> None:
    blocks = [(_views(3, 6), 0, [170.0, 175.0, 180.0]), (_views(3, 7), 1, [0.0, 5.0, 10.0])]
    x, _labels, _poses = _gallery(blocks)
    rec = _recognizer(blocks, 5)
    truth_0 = torch.tensor([-170.0, 175.0, 180.0])  # the first one 20 degrees off, or 340 unwrapped
    tests = [("first", 0, x[:3], truth_0), ("second", 1, x[[0, 4, 5]], torch.tensor([0.0, 5.0, 10.0]))]
    wrapped = score(rec, tests, wrap=True)
    assert wrapped.n_test == 6
    assert wrapped.per_object == {"first": 100.0, "second": pytest.approx(200.0 / 3)}
    assert wrapped.accuracy == pytest.approx(500.0 / 6)
    assert wrapped.pose_mae_deg == pytest.approx(20.0 / 5)
    assert score(rec, tests).pose_mae_deg == pytest.approx(340.0 / 5)


def test_score_without_a_correct_view_has_no_pose_error() -> None:
    blocks = [(_views(2, 8), 0, [0.0, 1.0]), (_views(2, 9), 1, [0.0, 1.0])]
    x, _labels, poses = _gallery(blocks)
    rec = _recognizer(blocks, 3)
    result = score(rec, [("wrong", 1, x[:2], poses[:2])])
    assert result.accuracy == 0.0 and result.per_object == {"wrong": 0.0}
    assert math.isnan(result.pose_mae_deg)


def _pose_tests(
    x: torch.Tensor, labels: torch.Tensor, poses: torch.Tensor
) -> list[tuple[str, int, torch.Tensor, torch.Tensor]]:
    """Each object's gallery views as its test views, their true poses one degree past the
    gallery's."""
    out = []
    for label in labels.unique().tolist():
        sel = (labels == label).nonzero()[:, 0]
        out.append((f"obj{label}", label, x[sel], poses[sel] + 1.0))
    return out


@pytest.mark.parametrize("workers", [1, 3])
def test_score_runs_the_pose_function_over_worker_threads(workers: int) -> None:
    """``workers`` threads measure the poses (``pose_fn``), one object's views each: the
    same scores as in this thread; each call sees the correctly recognized views of one
    object only."""
    blocks = [(_views(4, 20 + k), k, [10.0 * k + j for j in range(4)]) for k in range(5)]
    blocks = blocks
    x, labels, poses = _gallery(blocks)
    rec = _recognizer(blocks, 6)
    tests = _pose_tests(x, labels, poses)
    tests[2] = ("obj2", 3, tests[2][2], tests[2][3])  # recognized as 2, scored as 3: no view counts
    calls: list[tuple[list[int], str]] = []

    def pose_fn(views: torch.Tensor, got: torch.Tensor, rough: torch.Tensor) -> torch.Tensor:
        calls.append((sorted(set(got.tolist())), threading.current_thread().name))
        return rough + 0.25 * got.to(rough.dtype)  # the pose a label-dependent distance off

    here = score(rec, tests, pose_fn=pose_fn)
    here_calls = list(calls)
    calls.clear()
    there = score(rec, tests, pose_fn=pose_fn, workers=workers)
    assert (there.accuracy, there.per_object, there.n_test) == (here.accuracy, here.per_object, here.n_test)
    assert there.pose_mae_deg == here.pose_mae_deg and there.pose_median_deg == here.pose_median_deg
    # |rough + 0.25 k - (rough + 1)| over the recognized objects 0, 1, 3, 4.
    assert here.pose_mae_deg == pytest.approx(sum(abs(0.25 * k - 1.0) for k in (0, 1, 3, 4)) / 4)
    assert [c[0] for c in here_calls] == [[0], [1], [3], [4]]
    assert sorted(c[0] for c in calls) == [[0], [1], [3], [4]]  # the threads start in any order
    assert all(name.startswith("eigview-job") for _, name in calls)
    assert all(name == threading.current_thread().name for _, name in here_calls)


def test_score_raises_a_pose_functions_error_from_a_worker() -> None:
    blocks = [(_views(3, 30 + k), k, [0.0, 1.0, 2.0]) for k in range(3)]
    x, labels, poses = _gallery(blocks)
    rec = _recognizer(blocks, 4)

    def pose_fn(views: torch.Tensor, got: torch.Tensor, rough: torch.Tensor) -> torch.Tensor:
        raise ValueError(f"cannot place object {int(got[0])}")

    with pytest.raises(ValueError, match="cannot place object 0"):
        score(rec, _pose_tests(x, labels, poses), pose_fn=pose_fn, workers=2)


def test_score_checks_workers() -> None:
    blocks = [(_views(2, 40), 0, [0.0, 1.0])]
    x, _labels, poses = _gallery(blocks)
    rec = _recognizer(blocks, 1)
    with pytest.raises(ValueError, match="workers"):
        score(rec, [("a", 0, x, poses)], workers=-1)
