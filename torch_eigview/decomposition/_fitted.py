"""What the eigenspace estimators share: fitted-attribute access and input checks.

``FittedEstimator`` serves every estimator (linear and kernel); ``FittedEigenspace`` adds
the linear eigenspace's attributes, ``transform``, ``inverse_transform`` and ``to_module``,
shared by ``Eigenspace`` and ``StreamingEigenspace``, which differ only in how they fit.
"""

from __future__ import annotations

import math
from typing import ClassVar, Generic, Protocol, TypeVar

import torch

from torch_eigview.check import (
    check_finite,
    check_float_tensor,
    check_magnitude,
    check_n_components,
    check_ndim,
)
from torch_eigview.decomposition.linalg import EigenFit
from torch_eigview.errors import NotFittedError
from torch_eigview.nn.projection import EigenProjection

__all__ = ["FittedEigenspace", "FittedEstimator", "views_to_fit"]

DTYPES = (torch.float32, torch.float64)  # what torch.linalg decomposes


def views_to_fit(X: object) -> tuple[torch.Tensor, tuple[int, int, int] | None]:
    """Checks (P, N) or (P, C, H, W) float32/float64 finite views, P >= 2.

    Returns:
        The views as (P, N), detached, and the (C, H, W) of 4-D input (else None).

    Raises:
        TypeError: ``X`` is not a float32/float64 tensor.
        ValueError: bad shape, P < 2, N = 0, non-finite values, or values whose products
            overflow or underflow the dtype.
    """
    x = check_float_tensor(X, "X")
    if x.dtype not in DTYPES:
        raise TypeError(f"X must have dtype float32 or float64, got {x.dtype}")
    check_ndim(x, "X", (2, 4), "(P, N) or (P, C, H, W)")
    if x.shape[0] < 2:
        raise ValueError(f"X must hold at least 2 views (rows), got P={x.shape[0]}")
    if math.prod(x.shape[1:]) == 0:
        raise ValueError(f"X must hold at least one value per view (N >= 1), got shape {tuple(x.shape)}")
    flat = x.detach().reshape(x.shape[0], -1)
    # One min/max reduction (a read of the data, no mask the size of it written) proves
    # every value finite and the Gram products within the dtype's range, so an
    # overflow or underflow is named as such, not as "all views are identical".
    check_magnitude(flat, "X", max(flat.shape))
    image_shape = (x.shape[1], x.shape[2], x.shape[3]) if x.ndim == 4 else None
    return flat, image_shape


class FitRecord(Protocol):
    """What every fit record tells: the linear :class:`EigenFit` and the kernel fit."""

    @property
    def eigenvalues(self) -> torch.Tensor: ...  # (k,)
    @property
    def n_samples(self) -> int: ...
    @property
    def image_shape(self) -> tuple[int, int, int] | None: ...
    @property
    def n_components(self) -> int: ...
    @property
    def n_features(self) -> int: ...
    @property
    def dtype(self) -> torch.dtype: ...


FitT = TypeVar("FitT", bound=FitRecord)
E = TypeVar("E", bound="FittedEigenspace")


class FittedEstimator(Generic[FitT]):
    """Holds a fit record (None until fitted) and reads the attributes every estimator has.

    Constructor arguments are stored as given and validated when a fit starts
    (:meth:`_validate_params`), as scikit-learn's estimators do: ``set_params`` or an
    attribute set after construction is checked the same way.

    Args:
        n_components: k as an int >= 1, or an energy fraction in (0, 1).
    """

    _FIT_CALLS: ClassVar[str] = "fit"  # named by the not-fitted error

    def __init__(self, n_components: int | float = 15) -> None:
        self.n_components = n_components
        self._state: FitT | None = None

    def _validate_params(self) -> None:
        """Checks the constructor's arguments; every fit calls it before it reads any view.

        Raises:
            TypeError, ValueError: a bad argument; the message names it.
        """
        self.n_components = check_n_components(self.n_components)  # an integral k becomes an int

    def _fitted(self, what: str) -> FitT:
        if self._state is None:
            raise NotFittedError(
                f"this {type(self).__name__} is not fitted yet: call {self._FIT_CALLS} before {what}"
            )
        return self._state

    @property
    def eigenvalues_(self) -> torch.Tensor:
        """(k,) the kept eigenvalues, descending: λ of the centred scatter Xcᵀ Xc
        (scikit-learn's ``explained_variance_ * (P - 1)``), or of the centred kernel matrix."""
        return self._fitted("eigenvalues_").eigenvalues

    @property
    def n_components_(self) -> int:
        """k, the number of components kept."""
        return self._fitted("n_components_").n_components

    @property
    def n_samples_(self) -> int:
        """P, the number of views fitted."""
        return self._fitted("n_samples_").n_samples

    @property
    def n_features_in_(self) -> int:
        """N, the number of values per view."""
        return self._fitted("n_features_in_").n_features

    @property
    def image_shape_(self) -> tuple[int, int, int] | None:
        """(C, H, W) when fitted on (P, C, H, W) views (or given to ``fit_sparse``), else None."""
        return self._fitted("image_shape_").image_shape

    @staticmethod
    def _check_fitted_views(X: object, fit: FitRecord) -> torch.Tensor:
        """Checks views to project, (P, N) or (P, C, H, W) of the fitted N and dtype, finite;
        returns them as (P, N) (P may be 0)."""
        x = check_float_tensor(X, "X")
        check_ndim(x, "X", (2, 4), "(P, N) or (P, C, H, W)")
        if math.prod(x.shape[1:]) != fit.n_features:
            expected = f"(P, {fit.n_features})"
            if fit.image_shape is not None:
                expected += f" or (P, {', '.join(map(str, fit.image_shape))})"
            raise ValueError(f"X must have shape {expected} as fitted, got shape {tuple(x.shape)}")
        if x.dtype != fit.dtype:
            raise TypeError(f"X must have the fitted dtype {fit.dtype}, got {x.dtype}")
        # A finite sum proves every value finite; the exact check names what is not.
        if x.numel() and not bool(torch.isfinite(x.sum())):
            check_finite(x, "X")
        return x.detach().reshape(x.shape[0], fit.n_features)


class FittedEigenspace(FittedEstimator[EigenFit]):
    """The fitted linear eigenspace: its attributes, projections and frozen module."""

    @classmethod
    def from_fit(cls: type[E], fit: EigenFit, n_components: int | float | None = None) -> E:
        """An estimator holding ``fit``, as if it had fitted it.

        For fits computed elsewhere, e.g. by ``torch_eigview.scale.fit_distributed``.

        Args:
            fit: the fitted eigenspace.
            n_components: the estimator's ``n_components`` parameter (what was asked for,
                k or an energy fraction); None: the fit's k.

        Raises:
            TypeError: ``fit`` is not an :class:`~torch_eigview.decomposition.linalg.EigenFit`.
        """
        if not isinstance(fit, EigenFit):
            raise TypeError(f"fit must be an EigenFit, got {type(fit).__name__}")
        estimator = cls(fit.n_components if n_components is None else n_components)
        estimator._validate_params()
        estimator._state = fit
        return estimator

    @property
    def mean_(self) -> torch.Tensor:
        """(N,) the mean view."""
        return self._fitted("mean_").mean

    @property
    def components_(self) -> torch.Tensor:
        """(k, N) orthonormal eigenvectors, one per row, by decreasing eigenvalue."""
        return self._fitted("components_").components

    @property
    def explained_variance_(self) -> torch.Tensor:
        """(k,) variance along each component, λ / (P - 1) as in scikit-learn."""
        fit = self._fitted("explained_variance_")
        return fit.eigenvalues / (fit.n_samples - 1)

    @property
    def explained_variance_ratio_(self) -> torch.Tensor:
        """(k,) fraction of the total variance (over all eigenvalues) along each component."""
        return self._fitted("explained_variance_ratio_").ratio

    @staticmethod
    def _project(x: torch.Tensor, fit: EigenFit) -> torch.Tensor:
        """(P, k) coordinates of (P, N) views."""
        return (x - fit.mean) @ fit.components.T

    def transform(self, X: torch.Tensor) -> torch.Tensor:
        """Projects views onto the eigenspace.

        Args:
            X: (P, N) or (P, C, H, W) views with N = ``n_features_in_``, of the fitted dtype.

        Returns:
            (P, k) coordinates ``(X - mean_) @ components_.T``; (0, k) for P = 0.

        Raises:
            NotFittedError: before ``fit``.
            TypeError: ``X`` is not a float tensor of the fitted dtype.
            ValueError: ``X`` has the wrong number of features, or NaN or infinite values.
        """
        fit = self._fitted("transform")
        return self._project(self._check_fitted_views(X, fit), fit)

    def inverse_transform(self, Z: torch.Tensor) -> torch.Tensor:
        """Maps (P, k) coordinates back to (P, N) views ``Z @ components_ + mean_``.

        Reshape with ``image_shape_`` to get images back.

        Raises:
            NotFittedError: before ``fit``.
            TypeError: ``Z`` is not a float tensor of the fitted dtype.
            ValueError: ``Z`` is not (P, k).
        """
        fit = self._fitted("inverse_transform")
        z = check_float_tensor(Z, "Z")
        k = fit.n_components
        if z.ndim != 2 or z.shape[1] != k:
            raise ValueError(f"Z must have shape (P, {k}), got shape {tuple(z.shape)}")
        if z.dtype != fit.dtype:
            raise TypeError(f"Z must have the fitted dtype {fit.dtype}, got {z.dtype}")
        check_finite(z, "Z")
        return z @ fit.components + fit.mean

    def to_module(
        self, unit_norm: bool | None = None, image_shape: tuple[int, int, int] | None = None
    ) -> EigenProjection:
        """Returns the frozen ``EigenProjection`` (copies of mean, components, eigenvalues).

        Args:
            unit_norm: whether the module divides each input view by its L2 norm first.
                None (the default) means as fitted, the rule every ``to_module`` follows:
                the layer does to its input what the fit did to its views. This estimator
                fits the rows as given, so None is False; pass True when the rows given to
                ``fit`` were unit-norm (e.g. ``unit_rows(views)``) and the layer should
                normalize raw views the same way.
            image_shape: ``(C, H, W)`` of the views, for a fit on flattened (P, N) views;
                default the fitted one.

        Raises:
            NotFittedError: before ``fit``.
        """
        fit = self._fitted("to_module")
        shape = fit.image_shape if image_shape is None else image_shape
        unit = False if unit_norm is None else unit_norm  # as fitted: the rows as given
        return EigenProjection.from_tensors(fit.mean, fit.components, fit.eigenvalues, shape, unit_norm=unit)
