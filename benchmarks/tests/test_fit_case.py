"""One fit measured in its own process: the peak memory sampler and the cases."""

from __future__ import annotations

import pytest
import torch

from benchmarks._fit_case import PeakRss, measure, run_case
from benchmarks._views import smooth_views


def test_peak_rss_sees_an_allocation() -> None:
    with PeakRss() as peak:
        block = torch.ones(64, 2**20 // 4 * 4)  # 64 MiB, written so its pages are resident
        del block
    assert peak.mib > 32 and peak.children_mib == 0


def test_smooth_views_are_deterministic_turntable_sequences() -> None:
    views = smooth_views(3, 6, 2, 16)
    assert views.shape == (6, 2, 16, 16) and views.dtype == torch.float32
    assert torch.equal(views, smooth_views(3, 6, 2, 16)) and not torch.equal(views, smooth_views(4, 6, 2, 16))
    assert torch.equal(views[1, :, :, :-1], views[0, :, :, 1:])  # one pixel per view


def test_pipeline_case_runs() -> None:
    """The whole-build case (flow + synthesis into the cache, exact Gram from it) in this process."""
    row = run_case({"kind": "pipeline", "objects": 3, "size": 32, "channels": 3, "k": 3, "max_views": 41})
    assert row["passes"] > 1 and 0 < row["synthesis_s"] <= row["seconds"]


@pytest.mark.slow
def test_measure_runs_the_case_in_a_fresh_process() -> None:
    row = measure({"kind": "exact", "objects": 2, "size": 16, "channels": 1, "k": 3, "max_views": 41})
    assert row["method"] == "exact" and row["seconds"] > 0 and row["passes"] >= 2
    assert row["data_matrix_mib"] == pytest.approx(82 * 256 * 4 / 2**20)
