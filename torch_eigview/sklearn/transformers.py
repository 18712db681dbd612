"""The eigenspaces as scikit-learn transformers: :class:`EigenspacePCA` (``Eigenspace``) and
:class:`EigenspaceKernelPCA` (``KernelEigenspace``), with ``PCA``'s and ``KernelPCA``'s attributes."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from sklearn.base import BaseEstimator, ClassNamePrefixFeaturesOutMixin, TransformerMixin
from sklearn.utils.validation import check_array, check_is_fitted, validate_data

from torch_eigview.check import check_image_shape
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.method import resolve_components
from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.sklearn._common import FLOATS, check_bool, to_numpy, to_tensor

__all__ = ["EigenspaceKernelPCA", "EigenspacePCA"]


class _EigenspaceTransformer(ClassNamePrefixFeaturesOutMixin, TransformerMixin, BaseEstimator):
    """What the two eigenspace transformers share: fit, transform, tags, the layer."""

    n_components: int | float | None
    unit_norm: bool
    image_shape: tuple[int, int, int] | None
    eigenspace_: Eigenspace | KernelEigenspace

    def _make_space(self) -> Eigenspace | KernelEigenspace:
        raise NotImplementedError

    def _learned(self) -> None:
        """Copies the fitted tensors out of ``eigenspace_`` as NumPy attributes."""

    def _rows(self, x: torch.Tensor) -> torch.Tensor:
        return unit_rows(x) if self.unit_norm else x

    def fit(self, X: Any, y: Any = None) -> Any:
        """Fits on the (n_samples, n_features) rows of ``X``, n_samples >= 2; ``y`` is ignored.

        Returns:
            self, fitted.
        """
        X = validate_data(self, X, dtype=FLOATS, ensure_min_samples=2)
        check_bool(self.unit_norm, "unit_norm")
        self.image_shape_ = check_image_shape(self.image_shape, X.shape[1], "image_shape")
        space = self._make_space()
        x = self._rows(to_tensor(X))
        with torch.no_grad():
            space.fit(x if self.image_shape_ is None else x.reshape(-1, *self.image_shape_))
        self.eigenspace_ = space
        self.n_components_ = space.n_components_
        self._learned()
        return self

    def transform(self, X: Any) -> np.ndarray:
        """``(n_samples, n_features)`` rows → ``(n_samples, n_components_)`` coordinates, the fitted dtype."""
        check_is_fitted(self)
        X = validate_data(self, X, dtype=FLOATS, reset=False)
        x = to_tensor(X).to(self._dtype)
        with torch.no_grad():
            return to_numpy(self.eigenspace_.transform(self._rows(x)))

    @property
    def _dtype(self) -> torch.dtype:
        space = self.eigenspace_
        return space.mean_.dtype if isinstance(space, Eigenspace) else space.X_fit_.dtype

    @property
    def _n_features_out(self) -> int:
        """The number of output features, for ``get_feature_names_out``."""
        return int(self.n_components_)

    def __sklearn_tags__(self) -> Any:
        tags = super().__sklearn_tags__()
        tags.transformer_tags.preserves_dtype = ["float64", "float32"]
        return tags


class EigenspacePCA(_EigenspaceTransformer):
    """PCA by :class:`~torch_eigview.decomposition.eigenspace.Eigenspace`, as a scikit-learn transformer.

    Args:
        n_components: k (int >= 1), an energy fraction in (0, 1), or None: every component
            above the rank tolerance (the rank of the centred data).
        solver: ``Eigenspace``'s solver, "auto", "gram", "covariance" or "svd".
        unit_norm: scale each row to unit L2 norm before fitting and transforming
            (Murase and Nayar's brightness normalization).
        image_shape: (C, H, W) of the images the rows flatten (row-major), for
            :meth:`to_module`; None for other data.

    Attributes:
        mean_: (n_features,) the mean row.
        components_: ``(n_components_, n_features)`` orthonormal eigenvectors.
        eigenvalues_: ``(n_components_,)`` eigenvalues of the centred scatter matrix.
        explained_variance_: ``(n_components_,)`` ``eigenvalues_ / (n_samples - 1)``.
        explained_variance_ratio_: ``(n_components_,)`` fractions of the total variance.
        n_components_: k.
        eigenspace_: the fitted ``Eigenspace`` (torch tensors).

    Example:
        >>> X = np.random.default_rng(0).normal(size=(20, 6))
        >>> EigenspacePCA(3).fit_transform(X).shape
        (20, 3)
    """

    def __init__(
        self,
        n_components: int | float | None = None,
        *,
        solver: str = "auto",
        unit_norm: bool = False,
        image_shape: tuple[int, int, int] | None = None,
    ) -> None:
        self.n_components = n_components
        self.solver = solver
        self.unit_norm = unit_norm
        self.image_shape = image_shape

    def _make_space(self) -> Eigenspace:
        return Eigenspace(resolve_components(self.n_components), solver=self.solver)

    def _learned(self) -> None:
        space = self.eigenspace_
        assert isinstance(space, Eigenspace)
        self.mean_ = to_numpy(space.mean_)
        self.components_ = to_numpy(space.components_)
        self.eigenvalues_ = to_numpy(space.eigenvalues_)
        self.explained_variance_ = to_numpy(space.explained_variance_)
        self.explained_variance_ratio_ = to_numpy(space.explained_variance_ratio_)

    def inverse_transform(self, X: Any) -> np.ndarray:
        """``(n_samples, n_components_)`` coordinates → ``(n_samples, n_features)`` rows (unit-norm ones
        with ``unit_norm``)."""
        check_is_fitted(self)
        z = check_array(X, dtype=FLOATS)
        if z.shape[1] != self.n_components_:
            raise ValueError(f"X must have shape (n_samples, {self.n_components_}), got shape {z.shape}")
        assert isinstance(self.eigenspace_, Eigenspace)
        return to_numpy(self.eigenspace_.inverse_transform(to_tensor(z).to(self._dtype)))

    def to_module(self) -> EigenProjection:
        """The frozen layer (``unit_norm`` and ``image_shape`` as set)."""
        check_is_fitted(self)
        s = self.eigenspace_
        assert isinstance(s, Eigenspace)
        return EigenProjection.from_tensors(
            s.mean_, s.components_, s.eigenvalues_, self.image_shape_, unit_norm=self.unit_norm
        )


class EigenspaceKernelPCA(_EigenspaceTransformer):
    """Kernel PCA by :class:`~torch_eigview.decomposition.kernel.KernelEigenspace`, as a scikit-learn transformer.

    Args:
        n_components: k (int >= 1), an energy fraction in (0, 1), or None: every component
            with a positive eigenvalue above rounding.
        kernel: "rbf", "poly", "cosine" or "linear".
        gamma: γ of rbf and poly (> 0), "median" (rbf), or None: 1 / n_features.
        degree, coef0: of poly.
        nystrom: None (exact), or the number of Nyström landmark rows.
        unit_norm: scale each row to unit L2 norm before fitting and transforming.
        image_shape: (C, H, W) of the images the rows flatten, for :meth:`to_module`.

    Attributes:
        eigenvalues_: ``(n_components_,)`` eigenvalues of the centred kernel matrix.
        gamma_: the γ used.
        n_components_: k.
        eigenspace_: the fitted ``KernelEigenspace`` (torch tensors).

    Example:
        >>> X = np.random.default_rng(0).normal(size=(20, 6))
        >>> EigenspaceKernelPCA(3, gamma=0.1).fit_transform(X).shape
        (20, 3)
    """

    def __init__(
        self,
        n_components: int | float | None = None,
        *,
        kernel: str = "rbf",
        gamma: float | str | None = None,
        degree: int = 3,
        coef0: float = 1.0,
        nystrom: int | None = None,
        unit_norm: bool = False,
        image_shape: tuple[int, int, int] | None = None,
    ) -> None:
        self.n_components = n_components
        self.kernel = kernel
        self.gamma = gamma
        self.degree = degree
        self.coef0 = coef0
        self.nystrom = nystrom
        self.unit_norm = unit_norm
        self.image_shape = image_shape

    def _make_space(self) -> KernelEigenspace:
        return KernelEigenspace(
            resolve_components(self.n_components),
            kernel=self.kernel,
            gamma=self.gamma,
            degree=self.degree,
            coef0=self.coef0,
            nystrom=self.nystrom,
        )

    def _learned(self) -> None:
        space = self.eigenspace_
        assert isinstance(space, KernelEigenspace)
        self.eigenvalues_ = to_numpy(space.eigenvalues_)
        self.gamma_ = space.gamma_

    def to_module(self) -> KernelProjection:
        """The frozen layer (``unit_norm`` and ``image_shape`` as set)."""
        check_is_fitted(self)
        space = self.eigenspace_
        assert isinstance(space, KernelEigenspace)
        return space.to_module(unit_norm=self.unit_norm)
