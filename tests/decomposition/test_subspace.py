"""The subspace solver: against scikit-learn's full PCA, "auto"'s choice, its fallback, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from sklearn.decomposition import PCA

from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.decomposition import eigenspace, subspace
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.streaming import StreamingEigenspace
from torch_eigview.decomposition.subspace import default_tolerance, subspace_eigenpairs
from torch_eigview.nn.functional import unit_rows

from tests.decomposition.test_eigenspace import ATOL, RTOL, assert_close_up_to_sign, make_views


def _largest_angle(a: torch.Tensor, b: torch.Tensor) -> float:
    """The largest principal angle between the row spaces of (k, N) ``a`` and ``b``, from the
    sine (the projection's residual), exact for small angles where the arccosine of the
    cosines cannot resolve below about sqrt(eps)."""
    qa, qb = (torch.linalg.qr(m.double().T).Q for m in (a, b))
    return float(torch.linalg.svdvals(qb - qa @ (qa.T @ qb)).max().clamp(max=1).asin())


def _spy(monkeypatch: pytest.MonkeyPatch, result: str = "run") -> list[int]:
    """Counts the subspace solver's calls; ``result="none"`` makes it give up at once. The
    budget is lifted: at these sizes the exact products cost only two or three iterations."""
    monkeypatch.setattr(subspace, "iteration_budget", lambda *_: 100)
    calls: list[int] = []
    real = subspace.subspace_eigenpairs

    def spy(*args: object, **kwargs: object) -> object:
        calls.append(1)
        return None if result == "none" else real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(subspace, "subspace_eigenpairs", spy)
    return calls


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("shape", [(300, 500), (500, 300)])
def test_matches_sklearn_pca(
    shape: tuple[int, int], dtype: torch.dtype, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A block of k + 35 vectors much narrower than P and N: the iteration, not one pass
    over the whole row space, finds sklearn's leading components and eigenvalues."""
    calls = _spy(monkeypatch)
    n_views = shape[0]
    x = make_views(*shape)
    k = 8
    ref = PCA(n_components=k, svd_solver="full").fit(x.numpy())
    est = Eigenspace(k, solver="subspace").fit(x.to(dtype))
    assert calls == [1] and est.n_components_ == k and est.solver_ == "subspace"
    assert est.components_.dtype == dtype and est.eigenvalues_.dtype == dtype
    assert_close_up_to_sign(est.components_, ref.components_, dim=1, atol=ATOL[dtype])
    np.testing.assert_allclose(
        est.eigenvalues_.double().numpy(), ref.explained_variance_ * (n_views - 1), rtol=RTOL[dtype]
    )
    np.testing.assert_allclose(
        est.explained_variance_ratio_.double().numpy(), ref.explained_variance_ratio_, rtol=RTOL[dtype]
    )
    # The signs follow the same convention as the exact solvers'.
    exact = Eigenspace(k, solver="gram").fit(x.to(dtype))
    torch.testing.assert_close(est.components_, exact.components_, atol=ATOL[dtype], rtol=0)


def test_converges_to_the_tolerance_not_a_fixed_count() -> None:
    """Eigenvalues 0.8^i: each iteration shrinks the error by (λ_{l+1}/λ_k), so a tighter
    tolerance takes more iterations, and the residuals meet it."""
    x = make_views(400, 600)
    xc = x - x.mean(0)

    def products(v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        w = xc @ v
        return w, xc.T @ w

    runs = {}
    for tol in (1e-4, 1e-12):
        found = subspace_eigenpairs(products, 600, 6, x.dtype, x.device, max_iter=200, oversample=4, tol=tol)
        assert found is not None
        eigvals, comps, iters = found
        resid = (xc.T @ (xc @ comps.T) - comps.T * eigvals).norm(dim=0) / eigvals.sqrt()
        assert float(resid.max()) <= 2 * tol * float(eigvals[0].sqrt())
        runs[tol] = iters
    assert 1 < runs[1e-4] < runs[1e-12] < 200
    assert default_tolerance(torch.float32) == 1e-6 and default_tolerance(torch.float64) == 1e-12


def test_auto_picks_it_for_large_views_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """ "auto" takes the subspace solver for an int k when P and N reach SUBSPACE_MIN, the
    exact one otherwise (a fraction, or a small side), with the same eigenspace."""
    calls = _spy(monkeypatch)
    monkeypatch.setattr(eigenspace, "SUBSPACE_MIN", 60)
    x = make_views(250, 400)
    auto = Eigenspace(6).fit(x)
    assert calls == [1] and auto.solver_ == "subspace"
    torch.testing.assert_close(
        auto.components_, Eigenspace(6, solver="gram").fit(x).components_, atol=1e-8, rtol=0
    )
    Eigenspace(0.9).fit(x)
    Eigenspace(6).fit(x[:50])
    Eigenspace(50).fit(x[:80])  # k + 35 is past P: the block would be the whole row space
    assert calls == [1]


def test_falls_back_to_the_exact_solver(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the iteration does not converge within its budget the exact path runs, and
    the fit is the exact one bit for bit."""
    calls = _spy(monkeypatch, result="none")
    x = make_views(300, 500)
    got = Eigenspace(8, solver="subspace").fit(x)
    assert calls == [1] and got.solver_ == "gram"
    want = Eigenspace(8, solver="gram").fit(x)
    assert torch.equal(got.components_, want.components_) and torch.equal(got.eigenvalues_, want.eigenvalues_)


def test_budget_stops_a_flat_spectrum() -> None:
    """White noise has no gap to converge on: the iteration gives up after ``max_iter``, or
    at the third iteration where its rate shows it would not converge within them."""
    gen = torch.Generator().manual_seed(0)
    xc = torch.randn(300, 400, generator=gen, dtype=torch.float64)

    def products(v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        w = xc @ v
        return w, xc.T @ w

    assert subspace_eigenpairs(products, 400, 10, xc.dtype, xc.device, max_iter=3, oversample=5) is None
    # With a budget far beyond that it is stopped within a few iterations: its residuals
    # fall too slowly to reach the tolerance within the budget.
    calls: list[int] = []

    def counted(v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        calls.append(1)
        return products(v)

    assert subspace_eigenpairs(counted, 400, 10, xc.dtype, xc.device, max_iter=100, oversample=5) is None
    assert len(calls) < 10


def test_errors_and_rank() -> None:
    x = make_views(300, 500)
    with pytest.raises(ValueError, match=r"solver='subspace' needs an int n_components \(k\), got 0.9"):
        Eigenspace(0.9, solver="subspace").fit(x)
    low = make_views(300, 6)  # centred rank 6
    with pytest.raises(ValueError, match="n_components=7 exceeds the rank of X"):
        Eigenspace(7, solver="gram").fit(low)
    with pytest.raises(ValueError, match="n_components=7 exceeds the rank of X"):
        Eigenspace(7, solver="subspace").fit(torch.cat([low, torch.zeros(300, 494, dtype=low.dtype)], 1))
    same = torch.ones(300, 500, dtype=torch.float64)
    with pytest.raises(ValueError, match="rank 0 after centring"):
        Eigenspace(5, solver="subspace").fit(same)


def test_streaming_subspace_matches_the_explicit_fit(monkeypatch: pytest.MonkeyPatch) -> None:
    """One pass per iteration over 41-view blocks gathered into chunks: the eigenspace of
    the stacked views; "auto" takes it where ``Eigenspace``'s "auto" would, and the
    default is "exact"."""
    calls = _spy(monkeypatch)
    x = make_views(410, 500)
    blocks = list(x.split(41))
    got = StreamingEigenspace(8, solver="subspace").fit(blocks)
    want = Eigenspace(8, solver="gram").fit(x)
    torch.testing.assert_close(got.components_, want.components_, atol=1e-8, rtol=0)
    torch.testing.assert_close(got.eigenvalues_, want.eigenvalues_, atol=0, rtol=1e-10)
    torch.testing.assert_close(
        got.explained_variance_ratio_, want.explained_variance_ratio_, atol=0, rtol=1e-10
    )
    torch.testing.assert_close(got.mean_, want.mean_)
    assert calls == [1] and got.n_passes_ >= 3  # the mean, then at least two iterations
    assert got.solver_ == "subspace"
    monkeypatch.setattr(eigenspace, "SUBSPACE_MIN", 60)
    assert StreamingEigenspace(8).fit(blocks).solver_ == "exact"  # the default
    assert calls == [1]
    StreamingEigenspace(8, solver="auto").fit(blocks)
    assert calls == [1, 1]
    StreamingEigenspace(0.9, solver="auto").fit(blocks)
    assert calls == [1, 1]
    with pytest.raises(ValueError, match="solver='subspace' needs an int n_components"):
        StreamingEigenspace(0.9, solver="subspace").fit(blocks)
    assert StreamingEigenspace(0.9, solver="auto").fit(blocks).solver_ == "exact"
    assert StreamingEigenspace(8, solver="randomized").fit(blocks).solver_ == "randomized"
    assert StreamingEigenspace(8).solver_ is None and Eigenspace(8).solver_ is None


def test_streaming_falls_back_to_the_exact_passes(monkeypatch: pytest.MonkeyPatch) -> None:
    _spy(monkeypatch, result="none")
    x = make_views(410, 500)
    got = StreamingEigenspace(8, solver="subspace").fit(list(x.split(41)))
    want = StreamingEigenspace(8, solver="exact").fit(list(x.split(41)))
    assert torch.equal(got.components_, want.components_)
    assert got.n_passes_ == want.n_passes_  # the spy gave up before its first pass
    assert got.solver_ == want.solver_ == "exact"


@pytest.mark.slow
def test_auto_converges_within_its_budget_on_coil_views(
    folder: CoilFolder, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On real turntable images (every COIL-20 view 5 degrees apart and its mirror image,
    2880 × 16384, unit rows; "auto" admitted below SUBSPACE_MIN, whose budget is larger)
    the iteration converges within its real budget and spans the Gram solver's
    eigenspace (float32: both to about 1e-4 rad)."""
    x = torch.cat([folder.images(obj, list(range(0, 360, 5))) for obj in folder.objects])
    x = unit_rows(torch.cat([x, x.flip(-1)]))
    monkeypatch.setattr(eigenspace, "SUBSPACE_MIN", 2048)
    got = Eigenspace(15).fit(x)
    want = Eigenspace(15, solver="gram").fit(x)
    assert got.solver_ == "subspace" and want.solver_ == "gram"
    assert _largest_angle(got.components_, want.components_) < 1e-5
    torch.testing.assert_close(got.eigenvalues_, want.eigenvalues_, atol=0, rtol=1e-5)


def test_streaming_fallback_counts_the_passes(monkeypatch: pytest.MonkeyPatch) -> None:
    """White noise, budget 5: three real iterations (one pass each) before the rate stops
    it, then the exact path's passes, their mean pass shared: 1 + 3 + 2."""
    monkeypatch.setattr(subspace, "iteration_budget", lambda *_: 5)
    gen = torch.Generator().manual_seed(1)
    x = torch.randn(410, 500, generator=gen, dtype=torch.float64)
    got = StreamingEigenspace(8, solver="subspace").fit(list(x.split(41)))
    want = StreamingEigenspace(8, solver="exact").fit(list(x.split(41)))
    assert got.solver_ == "exact" and want.n_passes_ == 3
    assert got.n_passes_ == 1 + 3 + (want.n_passes_ - 1)
    assert torch.equal(got.components_, want.components_)


def test_a_failed_refit_keeps_the_record_consistent() -> None:
    """``solver_`` names the solver of the fit that holds, set only once a fit succeeds."""
    est = Eigenspace(5).fit(make_views(40, 12))
    assert est.solver_ == "covariance"
    with pytest.raises(ValueError, match="exceeds the rank"):
        est.fit(make_views(5, 50))  # 5 views: rank 4 after centring
    assert est.solver_ == "covariance"


def test_on_course_reads_no_rate_from_an_overflow() -> None:
    assert not subspace._on_course([math.inf, 5.0, 3.0], 3, 10)
    assert not subspace._on_course([4.0, 5.0, math.nan], 3, 10)
    assert subspace._on_course([100.0, 10.0, 1.5], 3, 10)  # rate 0.12: one more step
    assert not subspace._on_course([100.0, 90.0, 81.0], 3, 10)  # rate 0.9: about 42 more


def test_oversample_auto_is_each_methods_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """``oversample="auto"`` is SUBSPACE_OVERSAMPLE (35) for the subspace iteration and
    RANDOMIZED_OVERSAMPLE (10) for the range finder: the same fits bit for bit as those
    values given; another width gives another block (the same eigenspace to tolerance)."""
    from torch_eigview.decomposition.linalg import RANDOMIZED_OVERSAMPLE
    from torch_eigview.decomposition.subspace import SUBSPACE_OVERSAMPLE

    _spy(monkeypatch)
    x = make_views(300, 500)
    auto = Eigenspace(8, solver="subspace").fit(x)
    given = Eigenspace(8, solver="subspace", oversample=SUBSPACE_OVERSAMPLE).fit(x)
    narrow = Eigenspace(8, solver="subspace", oversample=4).fit(x)
    assert torch.equal(auto.components_, given.components_)
    assert not torch.equal(auto.components_, narrow.components_)
    assert _largest_angle(auto.components_, narrow.components_) < 1e-8
    blocks = list(x.split(41))
    for method, width in (("subspace", SUBSPACE_OVERSAMPLE), ("randomized", RANDOMIZED_OVERSAMPLE)):
        a = StreamingEigenspace(8, solver=method).fit(blocks)
        b = StreamingEigenspace(8, solver=method, oversample=width).fit(blocks)
        assert torch.equal(a.components_, b.components_), method
    assert repr(Eigenspace(8, oversample=4)) == "Eigenspace(n_components=8, solver='auto', oversample=4)"


@pytest.mark.parametrize(
    ("value", "error", "match"),
    [
        ("wide", ValueError, r"oversample='wide' must be 'auto' or an int >= 0"),
        (-1, ValueError, r"oversample=-1 must be >= 0"),
        (2.5, TypeError, r"oversample must be 'auto' or an int >= 0, got float 2.5"),
        (True, TypeError, r"oversample must be 'auto' or an int >= 0, got bool"),
    ],
)
def test_oversample_errors(value: object, error: type[Exception], match: str) -> None:
    x = make_views(12, 8)
    with pytest.raises(error, match=match):
        Eigenspace(5, oversample=value).fit(x)  # type: ignore[arg-type]
    with pytest.raises(error, match=match):
        StreamingEigenspace(5, oversample=value).fit(x)  # type: ignore[arg-type]


@pytest.mark.parametrize("method", ["exact", "subspace"])
def test_streamed_chunks_do_not_change_the_fit(monkeypatch: pytest.MonkeyPatch, method: str) -> None:
    """Blocks gathered into chunks of the default size or one block a chunk: the same
    eigenspace (the Gram entries are the same dot products; the subspace iteration's sums
    over chunks agree to rounding)."""
    import torch_eigview._tuning as _tuning

    _spy(monkeypatch)
    x = make_views(410, 500)
    blocks = list(x.split(41))
    want = StreamingEigenspace(8, solver=method, max_views=100).fit(blocks)
    monkeypatch.setattr(_tuning, "CHUNK_VIEWS", 1)
    got = StreamingEigenspace(8, solver=method, max_views=100).fit(blocks)
    assert got.solver_ == want.solver_ == method
    torch.testing.assert_close(got.components_, want.components_, atol=1e-10, rtol=0)
    torch.testing.assert_close(got.eigenvalues_, want.eigenvalues_, atol=0, rtol=1e-12)
