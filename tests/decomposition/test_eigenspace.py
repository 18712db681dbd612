"""Tests for ``Eigenspace``: scikit-learn's PCA as the reference, then invariants and errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.decomposition import PCA

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.errors import NotFittedError
from torch_eigview.nn.projection import EigenProjection

SOLVERS = ["gram", "covariance", "svd", "auto"]
SHAPES = [(20, 50), (40, 12)]  # (P, N): N > P (Gram is smaller) and N < P
# Components are unit vectors; the float32 error grows like eps32 * λ_1 / λ_k.
ATOL = {torch.float64: 1e-8, torch.float32: 1e-4}
RTOL = {torch.float64: 1e-10, torch.float32: 1e-4}


def make_views(
    n_views: int, n_features: int, dtype: torch.dtype = torch.float64, seed: int = 0
) -> torch.Tensor:
    """(P, N) views with a geometrically decaying spectrum (well separated eigenvalues) and
    a large offset, so that centring matters; rank after centring is min(P - 1, N)."""
    gen = torch.Generator().manual_seed(seed)
    m = min(n_views, n_features)
    scales = 0.8 ** torch.arange(m, dtype=torch.float64)
    latent = torch.randn(n_views, m, generator=gen, dtype=torch.float64) * scales
    x = latent @ torch.randn(m, n_features, generator=gen, dtype=torch.float64) + 3.0
    return x.to(dtype)


def assert_close_up_to_sign(actual: torch.Tensor, expected: np.ndarray, dim: int, atol: float) -> None:
    """Compares the vectors of ``actual`` (rows if ``dim`` is 1, columns if 0) up to sign each."""
    a = actual.double().numpy()
    if dim == 1:  # vectors are rows
        signs = np.sign(np.sum(a * expected, axis=1, keepdims=True))
    else:  # vectors are columns
        signs = np.sign(np.sum(a * expected, axis=0, keepdims=True))
    np.testing.assert_allclose(a * signs, expected, atol=atol, rtol=0)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("solver", SOLVERS)
def test_matches_sklearn_pca(solver: str, shape: tuple[int, int], dtype: torch.dtype) -> None:
    n_views, _ = shape
    x = make_views(*shape)
    k = 5
    ref = PCA(n_components=k, svd_solver="full").fit(x.numpy())
    est = Eigenspace(k, solver=solver).fit(x.to(dtype))
    atol, rtol = ATOL[dtype], RTOL[dtype]

    assert est.n_components_ == k and est.n_samples_ == n_views and est.n_features_in_ == shape[1]
    assert est.components_.dtype == dtype and est.eigenvalues_.dtype == dtype
    np.testing.assert_allclose(est.mean_.double().numpy(), ref.mean_, atol=atol * 10, rtol=0)
    assert_close_up_to_sign(est.components_, ref.components_, dim=1, atol=atol)
    expected_eig = ref.explained_variance_ * (n_views - 1)
    np.testing.assert_allclose(est.eigenvalues_.double().numpy(), expected_eig, rtol=rtol)
    np.testing.assert_allclose(est.explained_variance_.double().numpy(), ref.explained_variance_, rtol=rtol)
    np.testing.assert_allclose(
        est.explained_variance_ratio_.double().numpy(), ref.explained_variance_ratio_, rtol=rtol
    )
    z_ref = ref.transform(x.numpy())
    assert_close_up_to_sign(est.transform(x.to(dtype)), z_ref, dim=0, atol=atol * np.abs(z_ref).max())
    # Orthonormal rows.
    gram = est.components_.double() @ est.components_.double().T
    torch.testing.assert_close(gram, torch.eye(k, dtype=torch.float64), atol=atol, rtol=0)


@pytest.mark.parametrize("fraction", [0.5, 0.9, 0.99])
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("solver", SOLVERS)
def test_energy_fraction_picks_sklearn_k(solver: str, shape: tuple[int, int], fraction: float) -> None:
    x = make_views(*shape)
    ratio = PCA(svd_solver="full").fit(x.numpy()).explained_variance_ratio_
    # The paper's rule: the smallest k with sum_{i<=k} λ_i / sum_i λ_i >= fraction.
    k_ref = int(np.sum(np.cumsum(ratio) < fraction)) + 1
    est = Eigenspace(fraction, solver=solver).fit(x)
    assert 1 <= est.n_components_ < min(shape)
    assert est.n_components_ == k_ref
    assert float(est.explained_variance_ratio_.sum()) >= fraction


@pytest.mark.parametrize("solver", SOLVERS)
def test_signs_are_deterministic(solver: str) -> None:
    x = make_views(20, 50)
    first = Eigenspace(6, solver=solver).fit(x)
    second = Eigenspace(6, solver=solver).fit(x.clone())
    flipped = Eigenspace(6, solver=solver).fit(-x)
    torch.testing.assert_close(first.components_, second.components_, atol=0, rtol=0)
    torch.testing.assert_close(flipped.components_, first.components_, atol=1e-10, rtol=0)
    peak = first.components_.gather(1, first.components_.abs().argmax(1, keepdim=True))
    assert bool((peak > 0).all())
    # Same convention as scikit-learn (svd_flip with u_based_decision=False).
    ref = PCA(6, svd_solver="full").fit(x.numpy()).components_
    np.testing.assert_allclose(first.components_.numpy(), ref, atol=1e-8)


@pytest.mark.parametrize("solver", SOLVERS)
def test_image_input_and_exact_reconstruction(solver: str) -> None:
    x = make_views(20, 60).reshape(20, 3, 4, 5)
    rank = 19  # P - 1 after centring
    est = Eigenspace(rank, solver=solver).fit(x)
    assert est.image_shape_ == (3, 4, 5) and est.n_features_in_ == 60
    z = est.transform(x)
    torch.testing.assert_close(z, est.transform(x.reshape(20, 60)))
    assert z.shape == (20, rank)
    recon = est.inverse_transform(z)
    assert recon.shape == (20, 60)
    torch.testing.assert_close(recon, x.reshape(20, 60), atol=1e-10, rtol=0)
    assert Eigenspace(3, solver=solver).fit(x.reshape(20, 60)).image_shape_ is None


def test_reconstruction_when_n_below_p() -> None:
    x = make_views(40, 12)
    est = Eigenspace(12).fit(x)  # rank min(P - 1, N) = N
    torch.testing.assert_close(est.inverse_transform(est.transform(x)), x, atol=1e-10, rtol=0)


def test_fit_transform_and_to_module() -> None:
    x = make_views(20, 24).reshape(20, 1, 4, 6)
    est = Eigenspace(4)
    z = est.fit_transform(x)
    torch.testing.assert_close(z, est.transform(x))
    module = est.to_module()
    assert isinstance(module, EigenProjection)
    assert module.image_shape == (1, 4, 6)
    torch.testing.assert_close(module(x), z)
    torch.testing.assert_close(module.eigenvalues, est.eigenvalues_)
    module.mean.zero_()  # a copy: the estimator is unaffected
    assert float(est.mean_.abs().sum()) > 0


@pytest.mark.filterwarnings("ignore:Sparse CSR tensor support is in beta")
@pytest.mark.parametrize("layout", ["coo", "csr"])
@pytest.mark.parametrize("block_size", [3, 256])
def test_fit_sparse_equals_dense(layout: str, block_size: int) -> None:
    gen = torch.Generator().manual_seed(1)
    n_features, n_inner, n_views = 30, 40, 10
    g = torch.randn(n_features, n_inner, generator=gen, dtype=torch.float64)
    g = g * (torch.rand(n_features, n_inner, generator=gen) < 0.2)
    c = torch.randn(n_inner, n_views, generator=gen, dtype=torch.float64)
    c = c * (torch.rand(n_inner, n_views, generator=gen) < 0.5)
    to_sparse = torch.Tensor.to_sparse_csr if layout == "csr" else torch.Tensor.to_sparse
    dense = Eigenspace(5).fit((g @ c).T)
    est = Eigenspace(5).fit_sparse(to_sparse(g), to_sparse(c), image_shape=(1, 5, 6), block_size=block_size)
    assert est.image_shape_ == (1, 5, 6) and est.n_samples_ == n_views
    torch.testing.assert_close(est.mean_, dense.mean_)
    torch.testing.assert_close(est.components_, dense.components_)
    torch.testing.assert_close(est.eigenvalues_, dense.eigenvalues_)


def test_fit_sparse_errors() -> None:
    g = torch.eye(6, 4, dtype=torch.float64)
    c = torch.ones(4, 3, dtype=torch.float64)
    with pytest.raises(TypeError, match="G must be a sparse"):
        Eigenspace(1).fit_sparse(g, c.to_sparse())
    with pytest.raises(TypeError, match="C must be a sparse"):
        Eigenspace(1).fit_sparse(g.to_sparse(), c)
    with pytest.raises(ValueError, match=r"inner size M.*\(6, 4\).*\(5, 3\)"):
        Eigenspace(1).fit_sparse(g.to_sparse(), torch.ones(5, 3, dtype=torch.float64).to_sparse())
    with pytest.raises(TypeError, match="C must have the dtype of G"):
        Eigenspace(1).fit_sparse(g.to_sparse(), c.float().to_sparse())
    with pytest.raises(ValueError, match="block_size=0"):
        Eigenspace(1).fit_sparse(g.to_sparse(), c.to_sparse(), block_size=0)
    with pytest.raises(ValueError, match=r"image_shape=\(1, 2, 2\)"):
        Eigenspace(1).fit_sparse(g.to_sparse(), c.to_sparse(), image_shape=(1, 2, 2))
    bad = c.clone()
    bad[0, 0] = float("nan")
    with pytest.raises(ValueError, match="C must be finite"):
        Eigenspace(1).fit_sparse(g.to_sparse(), bad.to_sparse())


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_fit_rejects_non_finite(bad: float) -> None:
    x = make_views(5, 8)
    x[2, 3] = bad
    with pytest.raises(ValueError, match="X must be finite"):
        Eigenspace(2).fit(x)


def test_fit_errors() -> None:
    with pytest.raises(ValueError, match=r"at least 2 views.*P=1"):
        Eigenspace(1).fit(torch.randn(1, 8, dtype=torch.float64))
    with pytest.raises(
        ValueError, match=r"X must have shape \(P, N\) or \(P, C, H, W\), got shape \(2, 3, 4\)"
    ):
        Eigenspace(1).fit(torch.randn(2, 3, 4))
    with pytest.raises(TypeError, match=r"X must be a torch\.Tensor"):
        Eigenspace(1).fit(np.zeros((3, 4)))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="floating dtype"):
        Eigenspace(1).fit(torch.zeros(3, 4, dtype=torch.int64))
    with pytest.raises(ValueError, match=r"n_components=50 exceeds the rank of X \(19: 20 views, centred\)"):
        Eigenspace(50).fit(make_views(20, 60))
    with pytest.raises(ValueError, match="rank 0"):
        Eigenspace(1).fit(torch.ones(4, 6, dtype=torch.float64))


@pytest.mark.parametrize(
    ("value", "error", "match"),
    [
        (0, ValueError, "n_components=0 must be >= 1"),
        (-3, ValueError, "n_components=-3"),
        (1.5, ValueError, r"n_components=1.5 must be in \(0, 1\)"),
        (1.0, ValueError, r"must be in \(0, 1\)"),
        (0.0, ValueError, r"must be in \(0, 1\)"),
        (float("nan"), ValueError, r"must be in \(0, 1\)"),
        ("a", TypeError, "n_components must be an int"),
        (True, TypeError, "got bool True"),
        (None, TypeError, "n_components must be an int"),
    ],
)
def test_bad_n_components(value: object, error: type[Exception], match: str) -> None:
    est = Eigenspace(value)  # type: ignore[arg-type]  # stored as given, checked by fit
    assert est.n_components is value
    with pytest.raises(error, match=match):
        est.fit(make_views(6, 4))


def test_bad_solver() -> None:
    with pytest.raises(ValueError, match="solver='eig' must be one of"):
        Eigenspace(2, solver="eig").fit(make_views(6, 4))
    with pytest.raises(TypeError, match="solver must be a str"):
        Eigenspace(2, solver=1).fit_transform(make_views(6, 4))  # type: ignore[arg-type]
    est = Eigenspace(2)
    est.solver = "eig"  # set after construction: fit checks it the same way
    with pytest.raises(ValueError, match="solver='eig' must be one of"):
        est.fit(make_views(6, 4))


def test_transform_errors() -> None:
    est = Eigenspace(3).fit(make_views(10, 12).reshape(10, 1, 3, 4))
    with pytest.raises(
        ValueError, match=r"X must have shape \(P, 12\) or \(P, 1, 3, 4\).*got shape \(2, 13\)"
    ):
        est.transform(torch.zeros(2, 13, dtype=torch.float64))
    with pytest.raises(TypeError, match=r"fitted dtype torch\.float64, got torch\.float32"):
        est.transform(torch.zeros(2, 12))
    with pytest.raises(ValueError, match=r"Z must have shape \(P, 3\), got shape \(2, 4\)"):
        est.inverse_transform(torch.zeros(2, 4, dtype=torch.float64))


def test_not_fitted() -> None:
    est = Eigenspace(3)
    assert not hasattr(est, "components_")
    for name in ["mean_", "components_", "eigenvalues_", "explained_variance_ratio_", "n_components_"]:
        with pytest.raises(NotFittedError, match=f"not fitted yet.*{name}"):
            getattr(est, name)
    with pytest.raises(ValueError, match="not fitted yet"):
        est.transform(torch.zeros(2, 4))
    with pytest.raises(NotFittedError):
        est.to_module()


def test_repr() -> None:
    assert repr(Eigenspace()) == "Eigenspace(n_components=15, solver='auto')"
    assert repr(Eigenspace(0.99, solver="gram")) == "Eigenspace(n_components=0.99, solver='gram')"


@pytest.mark.parametrize("value", [0.5, 0.1])
@pytest.mark.parametrize("k", [15, 0.9, 0.1])
def test_identical_views_are_a_clear_error_for_every_k(value: float, k: float) -> None:
    """Identical views: with 0.5 the mean is exact and the centred Gram matrix zero (the
    leading-pairs solver must not leak a solver error); with 0.1 the float32 mean is not,
    and the centred views are rounding noise that must not pass for a component."""
    from torch_eigview.decomposition.streaming import StreamingEigenspace

    x = torch.full((300, 1, 16, 16), value)
    for space in (Eigenspace(k), StreamingEigenspace(k), StreamingEigenspace(k, solver="randomized")):
        with pytest.raises(ValueError, match="rank 0 after centring"):
            space.fit(x)
