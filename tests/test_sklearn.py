"""Tests for the scikit-learn estimators: agreement with scikit-learn's PCA and KernelPCA,
dtypes, Pipeline and GridSearchCV, and the whole method on rendered objects (scikit-learn's
own checks are in test_sklearn_checks.py)."""

from __future__ import annotations

import importlib
import sys

import numpy as np
import pytest
import torch

pytest.importorskip("sklearn")

from sklearn.base import clone
from sklearn.decomposition import PCA, KernelPCA
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline
from sklearn.utils.validation import check_is_fitted

from torch_eigview.datasets import OrthographicCamera, make_object, render_views
from torch_eigview.method import FewViewEigenspace
from torch_eigview.nn.functional import unit_rows
from torch_eigview.sklearn import (
    EigenspaceKernelPCA,
    EigenspacePCA,
    FewViewRecognizerClassifier,
)


def _data(dtype: type = np.float64, n: int = 30, d: int = 8) -> np.ndarray:
    return np.random.default_rng(0).normal(size=(n, d)).astype(dtype)


def _same_up_to_sign(a: np.ndarray, b: np.ndarray, **tol: float) -> None:
    sign = np.sign(np.sum(a * b, axis=0))
    np.testing.assert_allclose(a, b * sign, **tol)


def test_pca_agrees_with_scikit_learn() -> None:
    X = _data()
    ours, theirs = EigenspacePCA(4).fit(X), PCA(4).fit(X)
    np.testing.assert_allclose(ours.mean_, theirs.mean_, atol=1e-12)
    np.testing.assert_allclose(ours.explained_variance_, theirs.explained_variance_, rtol=1e-10)
    np.testing.assert_allclose(ours.explained_variance_ratio_, theirs.explained_variance_ratio_, rtol=1e-10)
    _same_up_to_sign(ours.components_.T, theirs.components_.T, atol=1e-10)
    _same_up_to_sign(ours.transform(X), theirs.transform(X), atol=1e-10)
    np.testing.assert_allclose(
        ours.inverse_transform(ours.transform(X)), theirs.inverse_transform(theirs.transform(X)), atol=1e-10
    )
    assert EigenspacePCA().fit(X).n_components_ == 8  # None: every component
    assert EigenspacePCA(0.9).fit(X).n_components_ == PCA(0.9, svd_solver="full").fit(X).n_components_


def test_kernel_pca_agrees_with_scikit_learn() -> None:
    X = _data()
    ours = EigenspaceKernelPCA(5, kernel="rbf", gamma=0.05).fit(X)
    theirs = KernelPCA(5, kernel="rbf", gamma=0.05).fit(X)
    np.testing.assert_allclose(ours.eigenvalues_, theirs.eigenvalues_, rtol=1e-9)
    _same_up_to_sign(ours.transform(X), theirs.transform(X), atol=1e-9)
    assert ours.gamma_ == 0.05


@pytest.mark.parametrize(
    "estimator", [EigenspacePCA(3), EigenspaceKernelPCA(3)], ids=lambda e: type(e).__name__
)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_numpy_in_numpy_out_dtype_kept(estimator: EigenspacePCA, dtype: type) -> None:
    X = _data(dtype)
    est = clone(estimator)
    with pytest.raises(NotFittedError):
        check_is_fitted(est)
    Z = est.fit(X).transform(X)
    check_is_fitted(est)
    assert isinstance(Z, np.ndarray) and Z.dtype == dtype and Z.shape == (30, 3)
    np.testing.assert_allclose(est.fit_transform(X), Z, rtol=1e-4, atol=1e-4)
    assert list(est.get_feature_names_out()) == [f"{type(est).__name__.lower()}{i}" for i in range(3)]
    ints = est.fit(X.astype(np.int64)).transform(X.astype(np.int64))
    assert ints.dtype == np.float64


def test_to_module_applies_the_layer() -> None:
    X = _data(n=12, d=2 * 3 * 4)
    for est in (
        EigenspacePCA(3, unit_norm=True, image_shape=(2, 3, 4)),
        EigenspaceKernelPCA(3, unit_norm=True, image_shape=(2, 3, 4)),
    ):
        layer = est.fit(X).to_module()
        assert layer.image_shape == (2, 3, 4) and layer.unit_norm
        images = torch.from_numpy(X).reshape(-1, 2, 3, 4)
        np.testing.assert_allclose(layer(images).detach().numpy(), est.transform(X), atol=1e-10)
    Z = EigenspacePCA(3, unit_norm=True).fit(X).transform(X)
    np.testing.assert_allclose(
        Z,
        EigenspacePCA(3)
        .fit(unit_rows(torch.from_numpy(X)).numpy())
        .transform(unit_rows(torch.from_numpy(X)).numpy()),
        atol=1e-10,
    )


def test_parameters_are_checked_by_fit() -> None:
    X = _data()
    for est, error, match in (
        (EigenspacePCA(n_components=0), ValueError, "n_components=0"),
        (EigenspacePCA(solver="qr"), ValueError, "solver="),
        (EigenspacePCA(unit_norm="yes"), TypeError, "unit_norm"),  # type: ignore[arg-type]
        (EigenspacePCA(image_shape=(1, 2, 3)), ValueError, "image_shape="),
        (EigenspaceKernelPCA(kernel="sigmoid"), ValueError, "kernel="),
        (FewViewRecognizerClassifier(image_shape=(2, 2, 3)), ValueError, "image_shape="),
        (FewViewRecognizerClassifier(synth=None, alpha="ten"), TypeError, "alpha"),  # type: ignore[arg-type]
    ):
        with pytest.raises(error, match=match):
            est.fit(X, np.arange(30) % 3)
    with pytest.raises(ValueError, match="angles must have shape"):
        FewViewRecognizerClassifier(synth=None).fit(X, np.arange(30) % 3, angles=[0.0, 1.0])


def test_pipeline_and_grid_search() -> None:
    rng = np.random.default_rng(1)
    centers = rng.normal(scale=4.0, size=(3, 10))
    y = np.repeat(np.array(["a", "b", "c"]), 20)
    X = centers[np.repeat(np.arange(3), 20)] + rng.normal(size=(60, 10))
    pipe = Pipeline([("pca", EigenspacePCA()), ("knn", KNeighborsClassifier(1))])
    search = GridSearchCV(pipe, {"pca__n_components": [2, 4], "pca__unit_norm": [False, True]}, cv=3).fit(
        X, y
    )
    assert search.best_score_ > 0.9
    assert search.best_estimator_.named_steps["pca"].n_components in (2, 4)
    kernel = Pipeline([("kpca", EigenspaceKernelPCA(4)), ("knn", KNeighborsClassifier(1))])
    assert GridSearchCV(kernel, {"kpca__gamma": [0.01, 0.1]}, cv=3).fit(X, y).best_score_ > 0.9
    clf = GridSearchCV(FewViewRecognizerClassifier(synth=None), {"n_components": [3, 5]}, cv=3).fit(X, y)
    assert clf.best_score_ > 0.9
    assert set(clf.predict(X)) == {"a", "b", "c"}


# ---------------------------------------------------------------------- the whole method, with synthesis

SHAPES = ("ellipsoid", "egg", "head")
CAMERA = OrthographicCamera(32)


def _views(angles: list[float]) -> np.ndarray:
    """(3·T, 32·32) rows: each object's views at ``angles``, object by object."""
    return np.concatenate([render_views(make_object(s), angles, CAMERA).flatten(1).numpy() for s in SHAPES])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_classifier_synthesizes(dtype: type) -> None:
    X = _views([0.0, 10.0]).astype(dtype)
    y = np.repeat(np.array(SHAPES), 2)
    clf = FewViewRecognizerClassifier(8, image_shape=(1, 32, 32)).fit(X, y, angles=[30.0, 40.0] * 3)
    assert clf.recognizer_.n_gallery == 3 * 51  # 20 degrees before the first seed to 20 past the last
    seeds = torch.from_numpy(X).reshape(3, 2, 1, 32, 32)[[1, 0, 2]]  # classes_ are sorted: egg first
    reference = FewViewEigenspace(8).fit(seeds, [30.0, 40.0])
    assert torch.equal(clf.recognizer_.codes, reference.recognizer_.codes)
    tests = _views([-5.0, 5.0, 20.0]).astype(dtype)
    assert clf.predict(tests).tolist() == np.repeat(np.array(SHAPES), 3).tolist()
    poses = clf.predict_pose(tests)
    assert isinstance(poses, np.ndarray) and poses.dtype == dtype and np.all((poses >= 10) & (poses <= 50))
    assert clf.score(tests, np.repeat(np.array(SHAPES), 3)) == 1.0
    # Without angles the rows of a label are 0, alpha, 2 alpha, ...: the same gallery up to the poses.
    plain = FewViewRecognizerClassifier(8, image_shape=(1, 32, 32)).fit(X, y)
    assert torch.equal(plain.recognizer_.codes, clf.recognizer_.codes)
    np.testing.assert_array_equal(plain.predict_pose(tests), poses - 30.0)
    layer = clf.to_module()
    assert layer.image_shape == (1, 32, 32) and layer.unit_norm


def test_classifier_in_a_pipeline_takes_angles() -> None:
    X = _views([0.0, 10.0])
    y = np.repeat(np.arange(3), 2)
    pipe = Pipeline(
        [("clf", FewViewRecognizerClassifier(4, image_shape=(1, 32, 32), synth=(-10.0, 10.0, 5.0)))]
    )
    pipe.fit(X, y, clf__angles=np.tile([100.0, 110.0], 3))
    assert pipe.predict(X).tolist() == y.tolist()
    at_zero = clone(pipe).fit(X, y)  # seeds at 0 and alpha = 10 degrees
    np.testing.assert_array_equal(
        pipe.named_steps["clf"].predict_pose(X), at_zero.named_steps["clf"].predict_pose(X) + 100.0
    )


def test_import_error_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, "torch_eigview.sklearn")
    monkeypatch.setitem(sys.modules, "sklearn.base", None)
    with pytest.raises(ImportError, match=r"pip install 'torch_eigview\[sklearn\]'"):
        importlib.import_module("torch_eigview.sklearn")
