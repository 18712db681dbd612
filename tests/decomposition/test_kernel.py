"""Tests for kernel PCA: ``KernelEigenspace`` against scikit-learn's ``KernelPCA`` and the
linear ``Eigenspace``, Nyström against the exact fit, ``KernelProjection`` (module checks,
ONNX against eager), and kernel PCA in the recognizer, the COIL experiment and the CLI."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest
import torch

from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.errors import NotFittedError
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer
from torch_eigview.synthesis import SynthesisOptions

from tests.helpers import check_module, rand

IMAGE_SHAPE = (1, 3, 4)
N_FEATURES = 12
K = 4
# (kernel, parameters) in sklearn's KernelPCA spelling; gamma None is 1/N in both.
SKLEARN_CASES = [
    ("rbf", {}),
    ("rbf", {"gamma": 0.7}),
    ("poly", {}),
    ("poly", {"gamma": 0.4, "degree": 2, "coef0": 0.5}),
    ("cosine", {}),
]


def views(p: int, seed: int = 0, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """(P, C, H, W) uniform views, centred at 0.5 so cosine sees varied angles."""
    return rand(p, *IMAGE_SHAPE, seed=seed, dtype=dtype) - 0.3


def same_up_to_sign(
    actual: torch.Tensor | np.ndarray, expected: torch.Tensor | np.ndarray, rel: float
) -> None:
    """Columns equal up to one sign each; the error is relative to the largest |expected|."""
    a, e = np.asarray(actual, dtype=np.float64), np.asarray(expected, dtype=np.float64)
    assert a.shape == e.shape
    signs = np.where((a * e).sum(axis=0) < 0, -1.0, 1.0)
    err = np.abs(a * signs - e).max() / np.abs(e).max()
    assert err <= rel, f"relative error {err:.3g} > {rel:.3g}"


# --------------------------------------------------------------------------- references
@pytest.mark.parametrize(("kernel", "params"), SKLEARN_CASES)
def test_matches_sklearn_kernel_pca(kernel: str, params: dict[str, float]) -> None:
    decomposition = pytest.importorskip("sklearn.decomposition")
    x, x_test = views(40), views(9, seed=1)
    est = KernelEigenspace(K, kernel=kernel, **params).fit(x)  # type: ignore[arg-type]
    ref = decomposition.KernelPCA(K, kernel=kernel, eigen_solver="dense", **params).fit(x.flatten(1).numpy())
    same_up_to_sign(est.transform(x_test), ref.transform(x_test.flatten(1).numpy()), 1e-4)
    same_up_to_sign(est.fit_transform(x), ref.transform(x.flatten(1).numpy()), 1e-4)
    np.testing.assert_allclose(est.eigenvalues_.numpy(), ref.eigenvalues_, rtol=1e-6)
    assert est.gamma_ == pytest.approx(ref.gamma_)


def test_linear_kernel_equals_linear_eigenspace() -> None:
    x, x_test = views(30), views(7, seed=1)
    kernel = KernelEigenspace(K, kernel="linear").fit(x)
    linear = Eigenspace(K).fit(x)
    same_up_to_sign(kernel.transform(x_test), linear.transform(x_test), 1e-10)
    torch.testing.assert_close(kernel.eigenvalues_, linear.eigenvalues_)
    # A callable kernel k(X, Y) = X Yᵀ is the same eigenspace.
    custom = KernelEigenspace(K, kernel=lambda a, b: a @ b.T).fit(x)
    torch.testing.assert_close(custom.transform(x_test), kernel.transform(x_test))


@pytest.mark.parametrize("kernel", ["rbf", "poly", "cosine", "linear"])
def test_fit_transform_equals_transform_with_fixed_signs(kernel: str) -> None:
    x = views(25)
    est = KernelEigenspace(K, kernel=kernel)
    scores = est.fit_transform(x)
    torch.testing.assert_close(scores, est.transform(x), atol=1e-10, rtol=1e-10)
    peaks = scores.gather(0, scores.abs().argmax(dim=0, keepdim=True))
    assert bool((peaks > 0).all())  # sklearn's svd_flip convention
    assert bool((est.eigenvalues_[:-1] >= est.eigenvalues_[1:]).all())
    assert est.coefficients_.shape == (25, K) and est.kernel_mean_.shape == (25,)
    assert est.X_fit_.shape == (25, N_FEATURES) and est.image_shape_ == IMAGE_SHAPE
    assert est.n_components_ == K and est.n_samples_ == 25 and est.n_features_in_ == N_FEATURES
    assert est.landmarks_ is None and est.w_inv_sqrt_ is None


def test_float32_close_to_float64() -> None:
    x = views(30)
    z64 = KernelEigenspace(K, kernel="rbf", gamma=0.5).fit(x).transform(x)
    z32 = KernelEigenspace(K, kernel="rbf", gamma=0.5).fit(x.float()).transform(x.float())
    assert z32.dtype == torch.float32
    same_up_to_sign(z32, z64, 1e-4)


def test_energy_fraction_and_median_gamma() -> None:
    x = views(30)
    est = KernelEigenspace(0.9, kernel="rbf", gamma="median").fit(x)
    flat = x.flatten(1)
    sq = torch.cdist(flat, flat).square()
    assert est.gamma_ == pytest.approx(1.0 / float(sq[torch.triu(torch.ones_like(sq), 1) > 0].median()))
    assert 1 <= est.n_components_ < 29


# --------------------------------------------------------------------------- Nyström
def test_nystrom_with_all_views_is_exact() -> None:
    x, x_test = views(30), views(6, seed=1)
    exact = KernelEigenspace(K, kernel="rbf", gamma=0.5).fit(x)
    full = KernelEigenspace(K, kernel="rbf", gamma=0.5, nystrom=30).fit(x)
    same_up_to_sign(full.transform(x_test), exact.transform(x_test), 1e-8)
    same_up_to_sign(full.fit_transform(x), exact.fit_transform(x), 1e-8)
    torch.testing.assert_close(full.eigenvalues_, exact.eigenvalues_)
    assert full.nystrom_error(x) < 1e-10


def test_nystrom_memory_and_error() -> None:
    x = views(60)
    errors = []
    for m in (6, 15, 30):
        est = KernelEigenspace(K, kernel="rbf", gamma=0.5, nystrom=m).fit(x)
        assert est.X_fit_.shape == (m, N_FEATURES) and est.coefficients_.shape == (m, K)
        assert est.landmarks_ is not None and est.landmarks_.tolist() == sorted(set(est.landmarks_.tolist()))
        assert est.landmarks_[0] == 0 and est.landmarks_[-1] == 59
        module = est.to_module()
        assert module.n_vectors == m
        torch.testing.assert_close(module(x), est.transform(x))
        errors.append(est.nystrom_error(x))
    print("Nyström ‖K − K̃‖_F/‖K‖_F for m = 6, 15, 30 of P = 60:", errors)
    assert 0 < errors[2] < errors[1] < errors[0] < 1


# --------------------------------------------------------------------------- the module
def make_module(kernel: str = "rbf", dtype: torch.dtype = torch.float64, **kw: object) -> KernelProjection:
    return (
        KernelEigenspace(K, kernel=kernel, gamma=0.5 if kernel != "cosine" else None)
        .fit(views(20, dtype=dtype))
        .to_module(**kw)
    )  # type: ignore[arg-type]


@pytest.mark.parametrize("kernel", ["rbf", "poly", "cosine", "linear"])
def test_module_equals_transform_and_keeps_invariants(kernel: str) -> None:
    est = KernelEigenspace(K, kernel=kernel, gamma=0.5 if kernel != "cosine" else None).fit(views(20))
    module = est.to_module()
    x = views(5, seed=3)
    torch.testing.assert_close(module(x), est.transform(x))
    torch.testing.assert_close(module(x.flatten(1)), module(x))
    check_module(module, (x,))
    assert list(module.parameters()) == []
    names = {name for name, _ in module.named_buffers()}
    assert names == {"vectors", "coefficients", "kernel_mean", "vectors_sqnorm", "eigenvalues"}


def test_module_unit_norm_and_gradients() -> None:
    x = views(20)
    unit = x / x.flatten(1).norm(dim=1).reshape(-1, 1, 1, 1)
    module = KernelEigenspace(K, kernel="rbf", gamma=1.0).fit(unit).to_module(unit_norm=True)
    torch.testing.assert_close(module(3.0 * x), module(unit))
    probe = views(2, seed=4).requires_grad_(True)
    assert torch.autograd.gradcheck(module, (probe,))


def test_module_state_dict_restores_kernel_and_repr() -> None:
    module = make_module("poly", unit_norm=True)
    fresh = KernelProjection.from_tensors(
        torch.zeros(20, N_FEATURES),
        torch.zeros(20, K),
        torch.zeros(20),
        kernel="rbf",
        eigenvalues=torch.zeros(K),
    ).double()
    buffer = io.BytesIO()
    torch.save(module.state_dict(), buffer)
    buffer.seek(0)
    fresh.load_state_dict(torch.load(buffer, weights_only=True))
    x = views(3, seed=5)
    torch.testing.assert_close(fresh(x), module(x), atol=0, rtol=0)
    assert fresh.kernel == "poly" and fresh.unit_norm and fresh.image_shape == IMAGE_SHAPE
    assert repr(module) == (
        "KernelProjection(in_features=12, n_components=4, n_vectors=20, kernel='poly', gamma=0.5, "
        "degree=3, coef0=1, image_shape=(1, 3, 4), unit_norm=True)"
    )


@pytest.mark.slow
def test_module_export_and_compile_equal_eager() -> None:
    module = make_module("rbf", torch.float32)
    batch = torch.export.Dim("batch")
    exported = torch.export.export(module, (views(3, dtype=torch.float32),), dynamic_shapes=({0: batch},))
    compiled = torch.compile(module, backend="aot_eager", fullgraph=True)
    for size in (1, 5):
        x = views(size, seed=size, dtype=torch.float32)
        torch.testing.assert_close(exported.module()(x), module(x))
        torch.testing.assert_close(compiled(x), module(x))


@pytest.mark.slow
@pytest.mark.parametrize("kernel", ["rbf", "poly", "cosine"])
def test_onnx_matches_eager(kernel: str, tmp_path: Path) -> None:
    onnxruntime = pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    module = make_module(kernel, torch.float32, unit_norm=True).eval()
    path = tmp_path / f"kernel_{kernel}.onnx"
    torch.onnx.export(
        module,
        (views(2, dtype=torch.float32),),
        str(path),
        dynamo=True,
        dynamic_shapes=({0: torch.export.Dim("batch")},),
        opset_version=18,
        verbose=False,
    )
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    name = session.get_inputs()[0].name
    for size in (1, 6):
        x = views(size, seed=10 + size, dtype=torch.float32)
        (actual,) = session.run(None, {name: x.numpy()})
        expected = module(x).detach().numpy()
        assert actual.shape == (size, K)
        assert np.abs(actual - expected).max() / np.abs(expected).max() <= 1e-5


def test_recognizer_accepts_kernel_projection() -> None:
    module = make_module("rbf")
    rec = NearestNeighborRecognizer.from_views(module, views(20), torch.arange(20) // 5, torch.zeros(20))
    assert rec.predict(views(20)[[0, 7, 19]]).labels.tolist() == [0, 1, 3]
    assert rec.projection is module


# --------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (dict(kernel="sigmoid"), ValueError, r"kernel='sigmoid' must be one of"),
        (dict(kernel=3), TypeError, r"kernel must be a str"),
        (dict(gamma=0.0), ValueError, r"gamma=0.0 must be a finite number > 0"),
        (dict(gamma=-1), ValueError, r"gamma=-1 must be"),
        (dict(gamma="auto"), ValueError, r"gamma='auto' must be None, 'median'"),
        (dict(kernel="poly", gamma="median"), ValueError, r"gamma='median' is a bandwidth for kernel='rbf'"),
        (dict(degree=0), ValueError, r"degree=0 must be >= 1"),
        (dict(degree=2.5), TypeError, r"degree must be an int"),
        (dict(nystrom=0), ValueError, r"nystrom=0 must be >= 1"),
        (dict(nystrom=True), TypeError, r"nystrom must be None or an int"),
        (dict(n_components=0), ValueError, r"n_components=0 must be >= 1"),
    ],
)
def test_argument_errors_at_fit(kwargs: dict[str, object], error: type[Exception], match: str) -> None:
    kwargs.setdefault("n_components", K)
    est = KernelEigenspace(**kwargs)  # type: ignore[arg-type]  # stored as given (scikit-learn's habit)
    assert all(getattr(est, name) is value for name, value in kwargs.items())
    with pytest.raises(error, match=match):
        est.fit(views(10))


def test_fit_and_transform_errors() -> None:
    est = KernelEigenspace(K, kernel="rbf")
    for use in (lambda: est.transform(views(2)), est.to_module, lambda: est.eigenvalues_):
        with pytest.raises(NotFittedError, match="not fitted yet"):
            use()
    bad = views(10)
    bad[3, 0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match=r"X must be finite"):
        est.fit(bad)
    with pytest.raises(ValueError, match=r"n_components=12 exceeds the number of positive eigenvalues"):
        KernelEigenspace(12, kernel="linear").fit(views(10))
    with pytest.raises(ValueError, match=r"nystrom=11 must be <= the number of views P=10"):
        KernelEigenspace(K, nystrom=11).fit(views(10))
    est.fit(views(10))
    with pytest.raises(ValueError, match=r"X must have shape \(P, 12\) or \(P, 1, 3, 4\) as fitted"):
        est.transform(torch.zeros(2, 13, dtype=torch.float64))
    with pytest.raises(TypeError, match=r"X must have the fitted dtype torch.float64"):
        est.transform(views(2, dtype=torch.float32))
    with pytest.raises(ValueError, match=r"nystrom_error needs a Nyström fit"):
        est.nystrom_error(views(3))
    with pytest.raises(TypeError, match=r"to_module needs a named kernel"):
        KernelEigenspace(K, kernel=lambda a, b: a @ b.T).fit(views(10)).to_module()
    with pytest.raises(ValueError, match=r"kernel\(X, Y\) must return a \(10, 10\) tensor"):
        KernelEigenspace(K, kernel=lambda a, b: a).fit(views(10))


def test_module_errors() -> None:
    with pytest.raises(TypeError, match=r"got a callable: a callable kernel cannot be exported"):
        KernelProjection.from_tensors(torch.eye(3), torch.ones(3, 1), torch.zeros(3), kernel=lambda a, b: a)
    with pytest.raises(ValueError, match=r"coefficients must have shape \(3, k\)"):
        KernelProjection.from_tensors(torch.eye(3), torch.ones(2, 1), torch.zeros(3))
    module = make_module("rbf")
    with pytest.raises(ValueError, match=r"x must have shape \(B, 12\) or \(B, 1, 3, 4\)"):
        module(torch.zeros(2, 13, dtype=torch.float64))
    with pytest.raises(TypeError, match=r"x must have a floating dtype"):
        module(torch.zeros(2, 12, dtype=torch.int32))
    # Any floating dtype is cast to the buffers' (float64 here).
    x = torch.rand(2, 12, dtype=torch.float64)
    torch.testing.assert_close(module(x.float()), module(x.float().double()), atol=0, rtol=0)


# --------------------------------------------------------------------------- COIL
@pytest.mark.coil
def test_coil_experiment_with_kernel_pca(folder: CoilFolder) -> None:
    common = dict(
        alpha=10.0,
        synth=(-5.0, 10.0, 5.0),
        test=(-10.0, 10.0),
        components=3,
        objects=[1, 2, 3],
        synthesis=SynthesisOptions(elevation=0.0),
    )
    result = CoilExperiment(**common, kernel="rbf", gamma="median").run(folder)  # type: ignore[arg-type]
    projection = result.recognizer.projection
    assert isinstance(projection, KernelProjection) and projection.kernel == "rbf"
    assert projection.unit_norm and projection.n_components == 3 and projection.n_vectors == 12
    assert result.n_train_views == 12 and result.n_test == 15
    assert result.accuracy >= 60.0
    with pytest.raises(ValueError, match=r"gamma=1.0 needs a kernel"):
        CoilExperiment(gamma=1.0)
    with pytest.raises(ValueError, match=r"kernel='laplace' must be one of"):
        CoilExperiment(kernel="laplace")


@pytest.mark.coil
def test_cli_kernel_option(coil_root: Path, tmp_path: Path) -> None:
    from torch_eigview.apps.cli import main
    from torch_eigview.io.model import load_model

    args = [
        "coil",
        "--folder",
        str(coil_root),
        "--alpha",
        "10",
        "--method",
        "dense",
        "--synth",
        "-10",
        "10",
        "5",
    ]
    args += [
        "--test",
        "-10",
        "10",
        "--objects",
        "1-2",
        "--components",
        "3",
        "--kernel",
        "poly",
        "--gamma",
        "2",
    ]
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert main(args) == 0
    assert "kernel PCA (poly, gamma=2)" in stdout.getvalue().splitlines()[0]
    with contextlib.redirect_stdout(io.StringIO()):  # a kernel model is saved like a linear one
        assert main([*args, "--save", str(tmp_path / "model.pt")]) == 0
    projection = load_model(tmp_path / "model.pt").recognizer.projection
    assert isinstance(projection, KernelProjection)
    assert (projection.kernel, projection.gamma, projection.degree) == ("poly", 2.0, 3)
