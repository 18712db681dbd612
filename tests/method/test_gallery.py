"""A gallery larger than max_views is merged as it is synthesized: the same recognizer as
the one fitted at once, below the rank cap, in memory bounded by a merge block."""

from __future__ import annotations

import pytest
import torch

from torch_eigview.datasets import OrthographicCamera, make_object, render_views
from torch_eigview.decomposition import Eigenspace, IncrementalEigenspace
from torch_eigview.method import FewViewEigenspace
from torch_eigview.method.gallery import held_out_quota
from torch_eigview.synthesis import SynthesisOptions

SHAPES = ("ellipsoid", "egg", "head", "cylinder")
OPTIONS = SynthesisOptions(flow="ilk", elevation=0.0)


@pytest.fixture(scope="module")
def seeds() -> torch.Tensor:
    camera = OrthographicCamera(24)
    return torch.stack([render_views(make_object(name), [0.0, 10.0], camera) for name in SHAPES]).double()


def _fit(seeds: torch.Tensor, **kw: object) -> FewViewEigenspace:
    est = FewViewEigenspace(6, synth=(-20.0, 20.0, 2.0), options=OPTIONS, **kw)  # type: ignore[arg-type]
    return est.fit(seeds, [0.0, 10.0], labels=list(SHAPES))


def test_merged_gallery_equals_the_one_fitted_at_once(seeds: torch.Tensor) -> None:
    at_once = _fit(seeds)
    merged = _fit(seeds, max_views=30, max_rank=84)  # 84 views: every merge exact
    assert isinstance(at_once.eigenspace_, Eigenspace)
    assert isinstance(merged.eigenspace_, IncrementalEigenspace)
    assert merged.eigenspace_.truncation_bound_ == 0.0
    torch.testing.assert_close(merged.eigenspace_.eigenvalues_, at_once.eigenspace_.eigenvalues_)
    a, b = at_once.recognizer_, merged.recognizer_
    torch.testing.assert_close(b.codes, a.codes, rtol=1e-7, atol=1e-9)
    assert torch.equal(b.labels, a.labels) and torch.equal(b.poses, a.poses)
    assert b.label_names == a.label_names == list(SHAPES)
    test = seeds[:, 1] * 0.97 + 0.01  # views near the gallery's
    assert torch.equal(merged.predict(test).labels, at_once.predict(test).labels)


def test_capped_rank_reports_its_bound(seeds: torch.Tensor) -> None:
    at_once = _fit(seeds)
    merged = _fit(seeds, max_views=30, max_rank=12)
    space = merged.eigenspace_
    assert isinstance(space, IncrementalEigenspace) and space.truncation_bound_ > 0
    low = at_once.eigenspace_.eigenvalues_ - space.eigenvalues_
    assert bool((low >= -1e-9).all()) and bool((low <= space.truncation_bound_ * (1 + 1e-9)).all())


def test_rejection_keeps_a_bounded_share_of_held_out_views(seeds: torch.Tensor) -> None:
    merged = _fit(seeds, max_views=40, max_rank=84, reject_rate=0.1)
    assert merged.n_calibration_views_ == len(SHAPES) * held_out_quota(40, len(SHAPES))
    assert merged.recognizer_.rejects
    at_once = _fit(seeds, reject_rate=0.1)
    assert at_once.n_calibration_views_ > merged.n_calibration_views_  # all of them, held at once


def test_a_kernel_gallery_is_fitted_at_once(seeds: torch.Tensor) -> None:
    est = _fit(seeds, max_views=30, kernel="rbf", gamma="median")
    assert not isinstance(est.eigenspace_, IncrementalEigenspace)


def test_max_rank_is_checked(seeds: torch.Tensor) -> None:
    with pytest.raises(ValueError, match=r"max_rank=4 must be at least n_components=6"):
        _fit(seeds, max_rank=4)
    with pytest.raises(ValueError, match=r"max_rank"):
        _fit(seeds, max_rank=0)
