"""IncrementalEigenspace against the exact eigenspace of the stacked views: equal below its
rank cap, within its reported bound above it."""

from __future__ import annotations

import pytest
import torch

from torch_eigview.decomposition import Eigenspace, IncrementalEigenspace
from torch_eigview.errors import NotFittedError

from tests.helpers import smooth_views


def _views(n_objects: int = 6, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """(6·41, 256) correlated views: objects sliding past the window."""
    return torch.cat([smooth_views(o, 41, 1, 16) for o in range(n_objects)]).flatten(1).to(dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("block", [1, 7, 41, 100])
def test_equals_the_exact_eigenspace_below_the_cap(dtype: torch.dtype, block: int) -> None:
    x = _views(dtype=dtype)
    exact = Eigenspace(10).fit(x)
    inc = IncrementalEigenspace(10, max_rank=256, keep_codes=True)
    for chunk in x.split(block):
        inc.partial_fit(chunk)
    tol = {"rtol": 1e-4, "atol": 1e-5} if dtype == torch.float32 else {"rtol": 1e-9, "atol": 1e-10}
    torch.testing.assert_close(inc.eigenvalues_, exact.eigenvalues_, **tol)
    torch.testing.assert_close(inc.mean_, exact.mean_, **tol)
    torch.testing.assert_close(inc.components_, exact.components_, **tol)  # the same sign rule
    # float32: the exact fit's own coordinates round at about 1e-5 of the largest.
    code_tol = {"rtol": 0.0, "atol": 1e-4} if dtype == torch.float32 else tol
    torch.testing.assert_close(inc.codes_, exact.transform(x), **code_tol)
    assert inc.truncation_bound_ == 0.0 and inc.discarded_energy_ == 0.0
    assert inc.n_samples_seen_ == x.shape[0] and inc.components_.dtype == dtype


def test_truncation_stays_within_its_bound() -> None:
    """Past the cap every kept eigenvalue lies below the exact one by at most the bound."""
    x = _views(8)
    exact = Eigenspace(5).fit(x)
    inc = IncrementalEigenspace(5, max_rank=12, keep_codes=True)
    for chunk in x.split(41):
        inc.partial_fit(chunk)
    low = exact.eigenvalues_ - inc.eigenvalues_
    assert inc.truncation_bound_ > 0 and 0 < inc.discarded_energy_ < 1
    assert bool((low >= -1e-9 * exact.eigenvalues_[0]).all())
    assert bool((low <= inc.truncation_bound_ * (1 + 1e-9)).all())


def test_fit_takes_a_tensor_or_blocks_and_an_energy_fraction() -> None:
    x = _views(3)
    by_tensor = IncrementalEigenspace(0.9, max_rank=200).fit(x.reshape(-1, 1, 16, 16))
    by_blocks = IncrementalEigenspace(0.9, max_rank=200).fit(list(x.split(50)))
    exact = Eigenspace(0.9).fit(x)
    assert by_tensor.n_components_ == by_blocks.n_components_ == exact.n_components_
    assert by_tensor.image_shape_ == (1, 16, 16)
    torch.testing.assert_close(by_blocks.eigenvalues_, exact.eigenvalues_)
    layer = by_tensor.to_module(unit_norm=False)
    torch.testing.assert_close(
        layer(x[:3].reshape(-1, 1, 16, 16)), exact.transform(x[:3]), rtol=1e-9, atol=1e-9
    )


def test_errors_name_the_argument() -> None:
    inc = IncrementalEigenspace(4, max_rank=8)
    with pytest.raises(NotFittedError):
        _ = inc.components_
    with pytest.raises(ValueError, match=r"max_rank=2 must be at least n_components=4"):
        IncrementalEigenspace(4, max_rank=2).partial_fit(torch.rand(5, 9, dtype=torch.float64))
    inc.partial_fit(torch.rand(5, 9, dtype=torch.float64))
    with pytest.raises(TypeError, match=r"X must have the first block's dtype torch.float64"):
        inc.partial_fit(torch.rand(5, 9))
    with pytest.raises(ValueError, match=r"X must hold views of the first block's shape|X must"):
        inc.partial_fit(torch.rand(5, 10, dtype=torch.float64))
    with pytest.raises(NotFittedError, match="keep_codes"):
        _ = inc.codes_
    with pytest.raises(ValueError, match=r"X must hold at least one view"):
        IncrementalEigenspace(2).fit([])
    with pytest.raises(ValueError, match=r"must be finite|NaN"):
        IncrementalEigenspace(2).partial_fit(torch.full((3, 4), float("nan")))


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("parts", [2, 3])
def test_merged_models_equal_one_model_of_every_view(dtype: torch.dtype, parts: int) -> None:
    """Models fitted apart (the ranks of a process group) and merged in order give the
    eigenvalues, components and every view's codes of one model fitted on all the views,
    and of the exact eigenspace, below the rank cap."""
    x = _views(dtype=dtype)
    exact = Eigenspace(10).fit(x)
    pieces = [IncrementalEigenspace(10, max_rank=256, keep_codes=True) for _ in range(parts)]
    for piece, chunk in zip(pieces, x.tensor_split(parts), strict=True):
        for block in chunk.split(41):  # each piece merged block by block, as a rank does
            piece.partial_fit(block)
    merged = IncrementalEigenspace(10, max_rank=256, keep_codes=True)
    for piece in pieces:
        merged.merge(piece)
    tol = {"rtol": 1e-4, "atol": 1e-5} if dtype == torch.float32 else {"rtol": 1e-9, "atol": 1e-10}
    torch.testing.assert_close(merged.eigenvalues_, exact.eigenvalues_, **tol)
    torch.testing.assert_close(merged.mean_, exact.mean_, **tol)
    torch.testing.assert_close(merged.components_, exact.components_, **tol)
    # float32: one rotation more than a block merge's, each rounding at the data's eps.
    code_tol = {"rtol": 0.0, "atol": 3e-4} if dtype == torch.float32 else tol
    torch.testing.assert_close(merged.codes_, exact.transform(x), **code_tol)
    assert merged.n_samples_seen_ == x.shape[0] and merged.truncation_bound_ == 0.0


def test_merge_errors_name_the_argument() -> None:
    x = _views(1)[:20]
    model = IncrementalEigenspace(3, keep_codes=True).fit(x)
    with pytest.raises(TypeError, match="other must be an IncrementalEigenspace, got Tensor"):
        model.merge(x)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="other must be fitted"):
        model.merge(IncrementalEigenspace(3))
    with pytest.raises(ValueError, match="other must keep its codes"):
        model.merge(IncrementalEigenspace(3).fit(x))
    with pytest.raises(
        ValueError, match=r"other must hold views of N=256 values of torch\.float64, got N=100"
    ):
        model.merge(IncrementalEigenspace(3, keep_codes=True).fit(x[:, :100]))
