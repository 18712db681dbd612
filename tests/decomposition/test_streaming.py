"""Tests for ``StreamingEigenspace``: the explicit ``Eigenspace`` as the reference."""

from __future__ import annotations

import itertools

import pytest
import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.streaming import StreamingEigenspace, blocks_of

from tests.helpers import smooth_views


def make_views(
    n_views: int, n_features: int, dtype: torch.dtype = torch.float64, seed: int = 0
) -> torch.Tensor:
    """(P, N) views with a geometrically decaying spectrum and an offset (centring matters)."""
    gen = torch.Generator().manual_seed(seed)
    m = min(n_views, n_features)
    latent = torch.randn(n_views, m, generator=gen, dtype=torch.float64) * 0.75 ** torch.arange(
        m, dtype=torch.float64
    )
    return (latent @ torch.randn(m, n_features, generator=gen, dtype=torch.float64) + 3.0).to(dtype)


def max_angle(a: torch.Tensor, b: torch.Tensor) -> float:
    """Largest principal angle (radians) between the row spaces of two orthonormal (k, N) bases."""
    s = torch.linalg.svdvals(a.double() @ b.double().T).clamp(max=1.0)
    return float(torch.arccos(s.min()))


ATOL = {torch.float64: 1e-10, torch.float32: 1e-5}


@pytest.mark.parametrize("shape", [(60, 200), (90, 30)], ids=["gram", "covariance"])
@pytest.mark.parametrize("max_views", [1, 25, 4096])
def test_exact_equals_eigenspace(shape: tuple[int, int], max_views: int, dtype: torch.dtype) -> None:
    x = make_views(*shape, dtype=dtype)
    ref = Eigenspace(8).fit(x)
    space = StreamingEigenspace(8, max_views=max_views).fit(blocks_of(x, 7))
    torch.testing.assert_close(space.mean_, ref.mean_, atol=ATOL[dtype], rtol=0)
    torch.testing.assert_close(space.components_, ref.components_, atol=ATOL[dtype], rtol=0)  # signs too
    torch.testing.assert_close(space.eigenvalues_, ref.eigenvalues_, rtol=ATOL[dtype], atol=0)
    torch.testing.assert_close(
        space.explained_variance_ratio_, ref.explained_variance_ratio_, rtol=1e-5, atol=0
    )
    assert space.components_.dtype == dtype and space.n_samples_ == shape[0]


@pytest.mark.parametrize(("n_features", "max_views"), [(900, 100), (900, 300), (60, 4096)])
def test_exact_chunks_uneven_blocks(n_features: int, max_views: int) -> None:
    """Blocks are gathered into chunks for the products (Gram path: later blocks against a
    panel, up to 256 views; scatter path, N = 60: up to N/2 views): blocks that fill a chunk
    exactly, overflow it, or are larger than one (the chunk is reallocated)."""
    x = make_views(700, n_features, seed=3)
    sizes = [7, 41, 41, 300, 1, 41, 129, 140]
    sizes.append(700 - sum(sizes))
    edges = torch.tensor([0, *sizes]).cumsum(0).tolist()
    blocks = [x[lo:hi] for lo, hi in itertools.pairwise(edges)]
    ref = Eigenspace(10).fit(x)
    space = StreamingEigenspace(10, max_views=max_views).fit(blocks)
    torch.testing.assert_close(space.components_, ref.components_, atol=1e-10, rtol=0)
    torch.testing.assert_close(space.eigenvalues_, ref.eigenvalues_, rtol=1e-10, atol=0)


def test_gram_passes_follow_panels() -> None:
    x = make_views(60, 200)
    assert StreamingEigenspace(5, max_views=4096).fit(blocks_of(x, 10)).n_passes_ == 3
    assert StreamingEigenspace(5, max_views=20).fit(blocks_of(x, 10)).n_passes_ == 5  # 3 panels


def test_energy_fraction_and_images() -> None:
    x = torch.cat([smooth_views(o, 41, 1, 16) for o in range(3)]).double()  # (123, 1, 16, 16)
    ref = Eigenspace(0.99).fit(x)
    blocks = [x[i : i + 41] for i in range(0, 123, 41)]  # one object per block
    space = StreamingEigenspace(0.99).fit(blocks)
    assert space.n_components_ == ref.n_components_
    assert space.image_shape_ == (1, 16, 16)
    torch.testing.assert_close(space.components_, ref.components_, atol=1e-8, rtol=0)
    assert space.to_module()(x[:2]).shape == (2, ref.n_components_)


@pytest.mark.parametrize("shape", [(80, 300), (200, 40)])
def test_randomized_close_to_exact(shape: tuple[int, int]) -> None:
    x = make_views(*shape)
    ref = Eigenspace(6).fit(x)
    space = StreamingEigenspace(6, solver="randomized", n_iter=3).fit(blocks_of(x, 16))
    assert max_angle(space.components_, ref.components_) < 1e-4
    torch.testing.assert_close(space.eigenvalues_, ref.eigenvalues_, rtol=1e-6, atol=0)
    assert space.n_passes_ == 6


def test_fit_transform_fits_from_the_stream() -> None:
    """fit_transform reads the source like fit, then projects it block by block (one pass more)."""
    x = make_views(60, 200)
    calls = []

    def source():  # type: ignore[no-untyped-def]
        calls.append(1)
        return (x[i : i + 10] for i in range(0, 60, 10))

    space = StreamingEigenspace(5)
    z = space.fit_transform(source)
    assert not isinstance(space, Eigenspace)
    assert len(calls) == 4 and space.n_passes_ == 4  # mean, Gram (one panel), components, projection
    torch.testing.assert_close(z, space.transform(x), atol=1e-12, rtol=0)
    torch.testing.assert_close(z, Eigenspace(5).fit_transform(x), atol=1e-10, rtol=0)


def test_generator_source_is_called_per_pass() -> None:
    x = make_views(30, 50)
    calls = []

    def source():  # type: ignore[no-untyped-def]
        calls.append(1)
        return (x[i : i + 10] for i in range(0, 30, 10))

    StreamingEigenspace(4).fit(source)
    assert len(calls) == 3  # mean, Gram (one panel), components


def test_not_regenerable_raises() -> None:
    x = make_views(30, 50)
    state = {"n": 0}

    def source():  # type: ignore[no-untyped-def]
        state["n"] += 1
        stop = 30 if state["n"] == 1 else 20
        return (x[i : i + 10] for i in range(0, stop, 10))

    with pytest.raises(ValueError, match="not re-generable"):
        StreamingEigenspace(4).fit(source)


@pytest.mark.parametrize("method", ["exact", "randomized"])
@pytest.mark.parametrize("bad_pass", [2, 3])
def test_non_finite_on_a_later_pass_raises(method: str, bad_pass: int) -> None:
    """Finiteness is scanned on the first pass only; a later pass that turns non-finite
    is caught in what the fit accumulates, never returned as a NaN eigenspace."""
    x = make_views(30, 50)
    state = {"n": 0}

    def source():  # type: ignore[no-untyped-def]
        state["n"] += 1
        y = x.clone()
        if state["n"] >= bad_pass:
            y[17, 4] = float("inf")
        return (y[i : i + 10] for i in range(0, 30, 10))

    with pytest.raises(ValueError, match="non-finite values on a later pass"):
        StreamingEigenspace(4, solver=method).fit(source)


def test_bad_blocks() -> None:
    x = make_views(30, 50)
    with pytest.raises(ValueError, match=r"like the first block"):
        StreamingEigenspace(4).fit([x[:10], x[10:, :40]])
    with pytest.raises(TypeError, match="first block's dtype"):
        StreamingEigenspace(4).fit([x[:10], x[10:].float()])
    bad = x.clone()
    bad[12, 3] = float("nan")
    with pytest.raises(ValueError, match="must be finite"):
        StreamingEigenspace(4).fit(blocks_of(bad, 10))
    # The error names the source's block (empty blocks count), found from its column sums.
    with pytest.raises(ValueError, match=r"blocks\[2\] must be finite, got 1 NaN"):
        StreamingEigenspace(4).fit([bad[:10], bad[:0], bad[10:20], bad[20:]])
    huge = x.clone()
    huge[3:5, 0] = 1e308  # finite, but the float64 sums overflow
    with pytest.raises(ValueError, match=r"blocks\[0\] is too large"):
        StreamingEigenspace(4).fit(blocks_of(huge, 10))
    with pytest.raises(ValueError, match="at least 2 views"):
        StreamingEigenspace(1).fit([x[:1]])
    with pytest.raises(TypeError, match="callable"):
        StreamingEigenspace(4).fit(3)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="exceeds the rank"):
        StreamingEigenspace(40).fit(blocks_of(x, 10))


def test_bad_arguments() -> None:
    x = torch.rand(8, 5, dtype=torch.float64)
    with pytest.raises(ValueError, match="solver='svd' must be one of"):
        StreamingEigenspace(4, solver="svd").fit(blocks_of(x, 4))
    with pytest.raises(ValueError, match="max_views=0"):
        StreamingEigenspace(4, max_views=0).fit(blocks_of(x, 4))
    with pytest.raises(TypeError, match="n_iter must be an int"):
        StreamingEigenspace(4, n_iter=1.5).fit_transform(blocks_of(x, 4))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="block_size=0"):
        blocks_of(torch.zeros(3, 3), 0)


def test_method_is_the_deprecated_name_of_solver() -> None:
    x = torch.rand(8, 5, dtype=torch.float64)
    with pytest.warns(DeprecationWarning, match="give solver="):
        old = StreamingEigenspace(3, method="randomized")
    assert old.solver == "randomized"
    old.fit(blocks_of(x, 4))
    with pytest.warns(DeprecationWarning, match="read solver_"):
        assert old.method_ == old.solver_ == "randomized"
    with pytest.warns(DeprecationWarning, match="read solver"):
        assert old.method == "randomized"
    with pytest.raises(TypeError, match="not both"), pytest.warns(DeprecationWarning):
        StreamingEigenspace(3, solver="auto", method="exact")
