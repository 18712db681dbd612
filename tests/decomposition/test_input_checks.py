"""Input checks of the eigenspace estimators: overflow and underflow named as such, NaN in
transform, empty batches, the streaming seed and a source whose values change."""

from __future__ import annotations

import pytest
import torch

from torch_eigview.decomposition import Eigenspace, KernelEigenspace, StreamingEigenspace

from tests.helpers import rand


@pytest.mark.parametrize(
    ("scale", "match"),
    [(1e18, "X is too large for torch.float32: its largest magnitude 1e\\+18"), (1e-25, "X is too small")],
)
def test_overflow_and_underflow_are_named(scale: float, match: str) -> None:
    x = rand(20, 16384, dtype=torch.float32) * scale
    with pytest.raises(ValueError, match=match):
        Eigenspace(5).fit(x)
    with pytest.raises(ValueError, match=match.replace("X is", "blocks is")):
        StreamingEigenspace(5).fit(x)


def test_float64_takes_the_same_scales() -> None:
    x = rand(20, 256) * 1e18
    ref = Eigenspace(5).fit(rand(20, 256))
    torch.testing.assert_close(Eigenspace(5).fit(x).eigenvalues_, ref.eigenvalues_ * 1e36)


def test_fit_sparse_magnitude() -> None:
    g = (torch.eye(6, dtype=torch.float32) * 1e30).to_sparse()
    c = rand(6, 4, dtype=torch.float32).to_sparse()
    with pytest.raises(ValueError, match="G·C is too large"):
        Eigenspace(2).fit_sparse(g, c)


@pytest.mark.parametrize("estimator", [Eigenspace(3), StreamingEigenspace(3), KernelEigenspace(3)])
def test_transform_empty_batch_and_nan(estimator: object) -> None:
    x = rand(12, 2, 3, 4)
    fitted = estimator.fit(x)  # type: ignore[attr-defined]
    assert fitted.transform(x[:0]).shape == (0, 3)
    assert fitted.transform(x[:0].reshape(0, 24)).shape == (0, 3)
    bad = x[:2].clone()
    bad[1, 0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match=r"X must be finite, got 1 NaN"):
        fitted.transform(bad)


def test_inverse_transform_nan() -> None:
    es = Eigenspace(3).fit(rand(12, 24))
    with pytest.raises(ValueError, match="Z must be finite"):
        es.inverse_transform(torch.full((1, 3), float("inf"), dtype=torch.float64))


def test_streaming_seed_checked_before_the_first_pass() -> None:
    passes = []

    def source() -> list[torch.Tensor]:
        passes.append(1)
        return [rand(4, 6)]

    est = StreamingEigenspace(3, solver="randomized", seed="x")  # type: ignore[arg-type]
    assert est.seed == "x"  # stored as given
    with pytest.raises(TypeError, match="seed must be an integer, got str 'x'"):
        est.fit(source)
    assert not passes  # not when the randomized solver draws its test matrix


@pytest.mark.parametrize("method", ["exact", "randomized"])
@pytest.mark.parametrize(
    "change",
    [lambda y: y.mul_(1.001), lambda y: y[:, :2].copy_(y[:, [1, 0]]), lambda y: y[5].add_(1e-3)],
    ids=["scaled", "columns-swapped", "one-view-shifted"],
)
def test_source_whose_values_change_between_passes(method: str, change: object) -> None:
    x = rand(30, 50)
    calls = {"n": 0}

    def source():  # type: ignore[no-untyped-def]
        calls["n"] += 1
        y = x.clone()
        if calls["n"] >= 2:
            change(y)  # type: ignore[operator]
        return (y[i : i + 10] for i in range(0, 30, 10))

    with pytest.raises(ValueError, match=r"not re-generable: blocks\[\d\] changed between passes"):
        StreamingEigenspace(4, solver=method).fit(source)


def test_unchanged_source_still_fits() -> None:
    x = rand(30, 50)
    ref = Eigenspace(4).fit(x)
    fit = StreamingEigenspace(4).fit(lambda: (x[i : i + 7].clone() for i in range(0, 30, 7)))
    torch.testing.assert_close(fit.eigenvalues_, ref.eigenvalues_)


def test_kernel_parameters_that_overflow_are_named() -> None:
    x = torch.tensor([[0.97], [0.71], [0.46]])
    with pytest.raises(
        ValueError, match=r"the rbf kernel of X, X is not finite in torch.float32 with gamma=1e\+300"
    ):
        KernelEigenspace(2, kernel="rbf", gamma=1e300).fit(x)


def test_views_without_features() -> None:
    with pytest.raises(ValueError, match=r"X must hold at least one value per view \(N >= 1\)"):
        Eigenspace(1).fit(torch.zeros(3, 0))
    with pytest.raises(ValueError, match=r"blocks\[0\] must hold at least one value per view"):
        StreamingEigenspace(1).fit([torch.zeros(3, 0)])
