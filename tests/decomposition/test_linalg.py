"""Tests for the linear-algebra core every estimator shares: the sign rule, the rank, the
fit record, and an estimator built from a record."""

from __future__ import annotations

import pytest
import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.linalg import EigenFit, eigh_descending, numerical_rank, peak_signs
from torch_eigview.decomposition.streaming import StreamingEigenspace


def test_peak_signs_rows_and_columns() -> None:
    x = torch.tensor([[1.0, -3.0, 2.0], [-0.5, 0.2, 0.1]], dtype=torch.float64)
    rows = peak_signs(x, dim=1)
    cols = peak_signs(x, dim=0)
    assert rows.shape == (2, 1) and cols.shape == (1, 3)
    assert rows.flatten().tolist() == [-1.0, -1.0]
    assert cols.flatten().tolist() == [1.0, -1.0, 1.0]
    # The two cases are one rule: columns of x are rows of xᵀ.
    torch.testing.assert_close(peak_signs(x.T.contiguous(), dim=1).T, cols, atol=0, rtol=0)


def test_eigh_descending_leading_pairs_equal_all_pairs() -> None:
    gen = torch.Generator().manual_seed(0)
    a = torch.randn(300, 40, generator=gen, dtype=torch.float64)
    s = a @ a.T  # (300, 300), rank 40: the leading-pairs (ARPACK) path runs for top <= 75
    w_top, v_top = eigh_descending(s, 5)
    w_all, v_all = eigh_descending(s)
    assert bool((w_all[:-1] >= w_all[1:]).all())
    torch.testing.assert_close(w_top, w_all[:5], rtol=1e-12, atol=0)
    torch.testing.assert_close((v_top * v_all[:, :5]).sum(0).abs(), torch.ones(5, dtype=torch.float64))


def test_eigh_descending_zero_matrix_takes_the_subset_solver() -> None:
    """ARPACK cannot start on a zero matrix (identical views): LAPACK's subset solver
    gives the leading pairs instead."""
    w, v = eigh_descending(torch.zeros(300, 300, dtype=torch.float64), 3)
    assert w.shape == (3,) and v.shape == (300, 3) and bool((w == 0).all())
    torch.testing.assert_close(v.T @ v, torch.eye(3, dtype=torch.float64))


def test_numerical_rank() -> None:
    eigvals = torch.tensor([4.0, 1.0, 1e-15, 0.0, -1e-15], dtype=torch.float64)
    assert numerical_rank(eigvals, 10, 10, torch.float64) == 2
    assert numerical_rank(torch.tensor([0.0, -1.0]), 10, 10, torch.float64) == 0
    # The centring's rounding (eps² ‖X‖²) lifts the tolerance above the product's.
    assert numerical_rank(eigvals, 10, 10, torch.float32, uncentred=1e15) == 0


def test_from_fit_round_trip() -> None:
    gen = torch.Generator().manual_seed(1)
    x = torch.randn(30, 12, generator=gen, dtype=torch.float64) + 2.0
    ref = Eigenspace(4).fit(x)
    fit = EigenFit(ref.mean_, ref.components_, ref.eigenvalues_, ref.explained_variance_ratio_, 30, None)
    space = Eigenspace.from_fit(fit)
    assert space.n_components == 4 and space.n_components_ == 4 and space.n_features_in_ == 12
    torch.testing.assert_close(space.transform(x), ref.transform(x), atol=0, rtol=0)
    assert StreamingEigenspace.from_fit(fit, 0.9).n_components == 0.9
    with pytest.raises(TypeError, match="fit must be an EigenFit"):
        Eigenspace.from_fit(ref)  # type: ignore[arg-type]


def test_from_eigenpairs_fixes_signs_and_dtype() -> None:
    comps = torch.tensor([[0.6, -0.8], [-0.8, -0.6]], dtype=torch.float64)
    fit = EigenFit.from_eigenpairs(
        torch.zeros(2),
        comps,
        torch.tensor([3.0, 1.0], dtype=torch.float64),
        torch.tensor(4.0),
        5,
        None,
        torch.float32,
    )
    assert fit.components.dtype == torch.float32 and fit.dtype == torch.float32
    assert fit.components.tolist() == [
        [-0.6000000238418579, 0.800000011920929],
        [0.800000011920929, 0.6000000238418579],
    ]
    assert fit.ratio.tolist() == [0.75, 0.25] and fit.n_components == 2 and fit.n_features == 2


def _decaying(n: int, rank: int, seed: int = 0) -> torch.Tensor:
    """A PSD (n, n) Gram of views whose spectrum decays, as image data's does."""
    gen = torch.Generator().manual_seed(seed)
    a = torch.randn(n, rank, generator=gen, dtype=torch.float64) * torch.logspace(
        0, -3, rank, dtype=torch.float64
    )
    return a @ a.T


def test_eigh_descending_leading_pairs_by_lanczos(monkeypatch: pytest.MonkeyPatch) -> None:
    import torch_eigview.decomposition.eigh as eigh

    def refuse(*_: object) -> None:
        raise AssertionError("ARPACK ran: the Lanczos iteration did not converge")

    monkeypatch.setattr(eigh, "_leading_by_arpack", refuse)
    s = _decaying(600, 200)
    w, v = eigh_descending(s, 15)
    w_all, v_all = torch.linalg.eigh(s)
    torch.testing.assert_close(w, w_all.flip(0)[:15], rtol=0, atol=1e-12 * float(w_all[-1]))
    torch.testing.assert_close((v * v_all.flip(1)[:, :15]).sum(0).abs(), torch.ones(15, dtype=torch.float64))
    torch.testing.assert_close(v.T @ v, torch.eye(15, dtype=torch.float64))
    w2, v2 = eigh_descending(s, 15)
    assert torch.equal(w, w2) and torch.equal(v, v2)  # a fixed start: the same pairs again


@pytest.mark.parametrize("case", ["flat", "low rank", "zero"])
def test_eigh_descending_hands_over_to_arpack(monkeypatch: pytest.MonkeyPatch, case: str) -> None:
    """White noise's flat spectrum does not converge within the budget (here 60 steps), a
    matrix of rank below ``top`` leaves fewer Lanczos directions than pairs asked, a zero
    matrix has none: ARPACK (or LAPACK's subset solver) gives the leading pairs."""
    import torch_eigview.decomposition.eigh as eigh

    gen = torch.Generator().manual_seed(1)
    a = torch.randn(400, 400, generator=gen, dtype=torch.float64)
    matrices = {"flat": a @ a.T, "low rank": a[:, :30] @ a[:, :30].T, "zero": torch.zeros(400, 400).double()}
    s = matrices[case]
    calls: list[int] = []
    arpack = eigh._leading_by_arpack

    def spy(matrix: torch.Tensor, top: int) -> tuple[torch.Tensor, torch.Tensor]:
        calls.append(top)
        return arpack(matrix, top)

    monkeypatch.setattr(eigh, "_leading_by_arpack", spy)
    w, v = eigh_descending(s, 50, lanczos_steps=60)
    assert calls == [50]
    w_all = torch.linalg.eigvalsh(s).flip(0)[:50]
    torch.testing.assert_close(w, w_all, rtol=0, atol=1e-9 * max(float(w_all.abs().max()), 1.0))
    torch.testing.assert_close(v.T @ v, torch.eye(50, dtype=torch.float64))


def test_eigh_descending_indefinite_gives_the_largest() -> None:
    """Lanczos finds both ends of a spectrum: the largest eigenvalues, not the largest in
    magnitude, of a matrix with large negative ones."""
    gen = torch.Generator().manual_seed(2)
    q = torch.linalg.qr(torch.randn(300, 300, generator=gen, dtype=torch.float64)).Q
    values = torch.cat([torch.logspace(2, -4, 150).double(), -torch.logspace(3, -4, 150).double()])
    s = (q * values) @ q.T
    w, v = eigh_descending((s + s.T) / 2, 10)
    torch.testing.assert_close(w, values[:10], rtol=1e-10, atol=0)
    torch.testing.assert_close(v.T @ v, torch.eye(10, dtype=torch.float64))
