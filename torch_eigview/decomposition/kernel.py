"""The ``KernelEigenspace`` estimator: kernel PCA of a set of views.

The paper's output is a data matrix of views interpolated in pose space (Sec. 1), so any
eigenspace method applies to it; this is kernel PCA (Schölkopf et al. 1998) as in
``sklearn.decomposition.KernelPCA``, with an optional Nyström approximation for many views.

Convention: a data matrix ``X`` is (P, N), one row per view (as in ``Eigenspace``). The
kernel matrix K = k(X, X) is centred in feature space, K_c = (I − 1/P) K (I − 1/P), and
eigen-decomposed, K_c α = λ α; a view x maps to (k(x, X) − k̄) α/√λ, scikit-learn's
``transform``, with k̄ the mean kernel row. With the linear kernel this is exactly the
linear eigenspace (K_c = Xc Xcᵀ, the Gram solver of ``Eigenspace``).

Nyström (Williams and Seeger 2001): with m landmark views L, C = k(X, L) (P, m) and
W = k(L, L) (m, m), K ≈ K̃ = C W⁺ Cᵀ = Φ Φᵀ with features Φ = C W^{-1/2}; centring Φ and
taking its PCA (an m×m eigenproblem) is exact kernel PCA of K̃, in P×m memory.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from torch_eigview.check import check_choice, check_finite, check_int, check_kernel_params
from torch_eigview.decomposition._fitted import FittedEstimator, views_to_fit
from torch_eigview.decomposition.linalg import choose_k, eigh_descending, numerical_rank, peak_signs
from torch_eigview.nn.kernel_projection import KERNELS, KernelProjection, pairwise_kernel

__all__ = ["KernelEigenspace"]

KernelFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


@dataclass(frozen=True)
class _KernelFit:
    vectors: torch.Tensor  # (T, N) training views, or the m Nyström landmarks
    coefficients: torch.Tensor  # (T, k)
    kernel_mean: torch.Tensor  # (T,)
    eigenvalues: torch.Tensor  # (k,)
    scores: torch.Tensor  # (P, k) the training views' coordinates
    gamma: float
    landmarks: torch.Tensor | None  # (m,) int64 indices into the training views
    w_inv_sqrt: torch.Tensor | None  # (m, r) W^{-1/2} on W's positive eigenspace
    n_samples: int
    image_shape: tuple[int, int, int] | None

    @property
    def n_components(self) -> int:
        """k."""
        return self.coefficients.shape[1]

    @property
    def n_features(self) -> int:
        """N."""
        return self.vectors.shape[1]

    @property
    def dtype(self) -> torch.dtype:
        """The dtype of every tensor of the record."""
        return self.vectors.dtype


def _eigh_symmetric(matrix: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """All eigenpairs of the symmetric part of a float64 (n, n) matrix, eigenvalues descending."""
    return eigh_descending((matrix + matrix.T) / 2)


class KernelEigenspace(FittedEstimator[_KernelFit]):
    """Kernel PCA of P views, fitted like a scikit-learn estimator.

    ``eigenvalues_`` are the eigenvalues λ of the centred kernel matrix (scikit-learn's
    ``KernelPCA.eigenvalues_``; with ``kernel="linear"`` they equal ``Eigenspace``'s).
    Eigenvalues are sorted in descending order; zero, negative and rounding-level ones
    are dropped; each component's training coordinate of largest magnitude is positive.

    Args:
        n_components: k as an int >= 1 (at most the number of positive eigenvalues), or a
            float in (0, 1): the smallest k whose eigenvalues hold that fraction of the
            positive eigenvalues' sum.
        kernel: "rbf" exp(−γ‖x − y‖²), "poly" (γ x·y + coef0)^degree, "cosine", "linear"
            x·y, or a callable ``k(X, Y)`` taking (P, N) and (Q, N) tensors and returning
            a (P, Q) tensor (usable eagerly, not by ``to_module``).
        gamma: γ of rbf and poly, > 0. None means 1/N (scikit-learn's default); "median"
            (rbf only) means 1/median of the squared distances between the training views
            (between the landmarks with Nyström), a common bandwidth heuristic.
        degree: degree of poly, an int >= 1.
        coef0: coef0 of poly.
        nystrom: None for exact kernel PCA (a P×P kernel matrix), or m, the number of
            Nyström landmark views (P×m memory). The landmarks are m evenly spaced training
            views, indices round(linspace(0, P − 1, m)): deterministic, and spread over the
            gallery's objects and poses when the views are stored in order.

    The arguments are stored as given and checked when a fit starts (scikit-learn's habit).

    Raises:
        TypeError: at fit, an argument has the wrong type.
        ValueError: at fit, an unknown kernel, gamma <= 0, degree < 1, nystrom < 1, or
            gamma="median" with a kernel other than rbf.

    Example:
        >>> X = torch.randn(20, 8, dtype=torch.float64)
        >>> KernelEigenspace(3, kernel="rbf", gamma=0.1).fit(X).transform(X).shape
        torch.Size([20, 3])
    """

    def __init__(
        self,
        n_components: int | float = 15,
        *,
        kernel: str | KernelFn = "rbf",
        gamma: float | str | None = None,
        degree: int = 3,
        coef0: float = 1.0,
        nystrom: int | None = None,
    ) -> None:
        super().__init__(n_components)
        self.kernel: str | KernelFn = kernel
        self.gamma: float | str | None = gamma
        self.degree = degree
        self.coef0 = coef0
        self.nystrom = nystrom

    def _validate_params(self) -> None:
        """Checks the arguments, stored as given (scikit-learn's habit); every fit calls it."""
        super()._validate_params()
        kernel, gamma = self.kernel, self.gamma
        if not (callable(kernel) and not isinstance(kernel, str)):
            check_choice(kernel, "kernel", KERNELS)
        if gamma == "median":
            if kernel != "rbf":
                raise ValueError(
                    f"gamma='median' is a bandwidth for kernel='rbf' only, got kernel={kernel!r}"
                )
            check_kernel_params(None, self.degree, self.coef0)
        else:
            if isinstance(gamma, str):
                raise ValueError(f"gamma={gamma!r} must be None, 'median' or a number > 0")
            check_kernel_params(gamma, self.degree, self.coef0)
        try:  # None (exact kernel PCA) or the number of landmark views
            None if self.nystrom is None else check_int(self.nystrom, "nystrom", 1)
        except TypeError:
            raise TypeError(
                f"nystrom must be None or an int >= 1, got {type(self.nystrom).__name__} {self.nystrom!r}"
            ) from None

    def __repr__(self) -> str:
        kernel = self.kernel if isinstance(self.kernel, str) else getattr(self.kernel, "__name__", "callable")
        text = f"KernelEigenspace(n_components={self.n_components!r}, kernel={kernel!r}"
        if self.gamma is not None:
            text += f", gamma={self.gamma!r}"
        if self.kernel == "poly":
            text += f", degree={self.degree}, coef0={self.coef0:g}"
        if self.nystrom is not None:
            text += f", nystrom={self.nystrom}"
        return text + ")"

    # ------------------------------------------------------------------ fitted attributes
    @property
    def X_fit_(self) -> torch.Tensor:
        """(T, N) the views kernel rows are taken against: all P training views, or the m landmarks."""
        return self._fitted("X_fit_").vectors

    @property
    def coefficients_(self) -> torch.Tensor:
        """(T, k) centred kernel row → coordinates: α/√λ (sklearn's scaled eigenvectors), or W^{-1/2}U."""
        return self._fitted("coefficients_").coefficients

    @property
    def kernel_mean_(self) -> torch.Tensor:
        """(T,) the mean kernel row k̄ of the training views (sklearn's ``K_fit_rows_``)."""
        return self._fitted("kernel_mean_").kernel_mean

    @property
    def gamma_(self) -> float:
        """The γ used (1/N when ``gamma`` was None, 1/median when "median")."""
        return self._fitted("gamma_").gamma

    @property
    def landmarks_(self) -> torch.Tensor | None:
        """(m,) int64 indices of the Nyström landmark views, or None for exact kernel PCA."""
        return self._fitted("landmarks_").landmarks

    @property
    def w_inv_sqrt_(self) -> torch.Tensor | None:
        """(m, r) W^{-1/2} on the landmark kernel's positive eigenspace (Nyström), or None."""
        return self._fitted("w_inv_sqrt_").w_inv_sqrt

    # ------------------------------------------------------------------ kernels
    def _kernel(self, x: torch.Tensor, y: torch.Tensor, gamma: float, name: str) -> torch.Tensor:
        if isinstance(self.kernel, str):
            out = pairwise_kernel(x, y, self.kernel, gamma, self.degree, self.coef0)
            if out.numel() and not bool(torch.isfinite(out.sum())) and not bool(torch.isfinite(out).all()):
                raise ValueError(
                    f"the {self.kernel} kernel of {name} is not finite in {x.dtype} with gamma={gamma:g}, "
                    f"degree={self.degree}, coef0={self.coef0:g}: the parameters overflow it (a smaller gamma "
                    "or degree, or float64 views)"
                )
            return out
        out = self.kernel(x, y)
        if not isinstance(out, torch.Tensor) or tuple(out.shape) != (x.shape[0], y.shape[0]):
            got = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
            raise ValueError(
                f"kernel(X, Y) must return a ({x.shape[0]}, {y.shape[0]}) tensor for {name}, got {got}"
            )
        check_finite(out, f"kernel({name})")
        return out.to(x.dtype)

    def _resolve_gamma(self, vectors: torch.Tensor) -> float:
        if self.gamma is None:
            return 1.0 / vectors.shape[1]
        if self.gamma != "median":
            return float(self.gamma)
        sq = torch.cdist(vectors.double(), vectors.double()).square()
        pairs = sq[tuple(torch.triu_indices(sq.shape[0], sq.shape[0], 1, device=sq.device))]
        median = float(pairs.median()) if pairs.numel() else 0.0
        if not median > 0:
            raise ValueError(
                "gamma='median' needs views at distinct positions: the median squared distance is 0"
            )
        return 1.0 / median

    # ------------------------------------------------------------------ fitting
    def fit(self, X: torch.Tensor) -> KernelEigenspace:
        """Fits kernel PCA on the views ``X``.

        Args:
            X: (P, N) or (P, C, H, W) float32/float64 views, P >= 2, finite.

        Returns:
            self, fitted.

        Raises:
            TypeError: ``X`` is not a float32/float64 tensor.
            ValueError: bad shape, P < 2, non-finite values, ``nystrom`` > P, or an int
                ``n_components`` larger than the number of positive eigenvalues.
        """
        self._validate_params()
        x, image_shape = views_to_fit(X)
        with torch.no_grad():
            if self.nystrom is None:
                self._state = self._fit_exact(x, image_shape)
            else:
                self._state = self._fit_nystrom(x, image_shape)
        return self

    def fit_transform(self, X: torch.Tensor) -> torch.Tensor:
        """Fits on ``X`` (P, N) or (P, C, H, W) and returns its (P, k) coordinates (α√λ)."""
        return self.fit(X)._fitted("fit_transform").scores

    def _choose_k(self, eigvals: torch.Tensor, rank: int, what: str) -> int:
        return choose_k(
            self.n_components,
            eigvals,
            eigvals[:rank].sum(),
            rank,
            empty=f"the centred {what} has no positive eigenvalue: all views look the same to it",
            bound=f"the number of positive eigenvalues of the centred {what} ({rank})",
        )

    def _fit_exact(self, x: torch.Tensor, image_shape: tuple[int, int, int] | None) -> _KernelFit:
        n_views, n_features = x.shape
        gamma = self._resolve_gamma(x)
        # The P×P eigenproblem runs in float64 (as Eigenspace's Gram solver); the kernel
        # itself is evaluated in the input dtype, like the exported forward.
        k = self._kernel(x, x, gamma, "X, X").double()
        kernel_mean = k.mean(dim=0)
        k_c = k - kernel_mean[None, :] - kernel_mean[:, None] + kernel_mean.mean()
        eigvals, eigvecs = _eigh_symmetric(k_c)
        rank = numerical_rank(eigvals, n_views, n_features, x.dtype)
        n_keep = self._choose_k(eigvals, rank, "kernel matrix")
        eigvals = eigvals[:n_keep]
        # Eigenvectors of K_c with λ > 0 are orthogonal to the constant vector (K_c 1 = 0);
        # removing their mean makes that exact, so the forward may skip the test-side
        # centring term (it multiplies 1ᵀα).
        alphas = eigvecs[:, :n_keep]
        alphas = alphas - alphas.mean(dim=0)
        scores = alphas * eigvals.sqrt()
        sign = peak_signs(scores, dim=0)
        return _KernelFit(
            vectors=x.clone(),
            coefficients=(alphas * sign / eigvals.sqrt()).to(x.dtype).contiguous(),
            kernel_mean=kernel_mean.to(x.dtype),
            eigenvalues=eigvals.to(x.dtype),
            scores=(scores * sign).to(x.dtype),
            gamma=gamma,
            landmarks=None,
            w_inv_sqrt=None,
            n_samples=n_views,
            image_shape=image_shape,
        )

    def _fit_nystrom(self, x: torch.Tensor, image_shape: tuple[int, int, int] | None) -> _KernelFit:
        n_views, n_features = x.shape
        m = self.nystrom
        assert m is not None
        if m > n_views:
            raise ValueError(f"nystrom={m} must be <= the number of views P={n_views}")
        index = torch.linspace(0, n_views - 1, m, dtype=torch.float64).round().long().to(x.device)
        landmarks = x[index].clone()
        gamma = self._resolve_gamma(landmarks)
        w_vals, w_vecs = _eigh_symmetric(self._kernel(landmarks, landmarks, gamma, "L, L").double())
        r = numerical_rank(w_vals, m, n_features, x.dtype)
        if r == 0:
            raise ValueError("the landmark kernel matrix W has no positive eigenvalue")
        # W⁺ restricted to W's positive eigenspace, so Φ Φᵀ = C W⁺ Cᵀ.
        w_inv_sqrt = w_vecs[:, :r] / w_vals[:r].sqrt()
        c = self._kernel(x, landmarks, gamma, "X, L").double()  # (P, m): the only P-sized matrix
        kernel_mean = c.mean(dim=0)
        features = (c - kernel_mean) @ w_inv_sqrt  # centred Φ, (P, r)
        eigvals, eigvecs = _eigh_symmetric(features.T @ features)
        rank = numerical_rank(eigvals, m, n_features, x.dtype)
        n_keep = self._choose_k(eigvals, rank, "Nyström kernel matrix")
        eigvals, axes = eigvals[:n_keep], eigvecs[:, :n_keep]
        scores = features @ axes  # = K̃_c α/√λ for the training views
        sign = peak_signs(scores, dim=0)
        return _KernelFit(
            vectors=landmarks,
            coefficients=(w_inv_sqrt @ axes * sign).to(x.dtype).contiguous(),
            kernel_mean=kernel_mean.to(x.dtype),
            eigenvalues=eigvals.to(x.dtype),
            scores=(scores * sign).to(x.dtype),
            gamma=gamma,
            landmarks=index,
            w_inv_sqrt=w_inv_sqrt.to(x.dtype),
            n_samples=n_views,
            image_shape=image_shape,
        )

    # ------------------------------------------------------------------ inference
    def _check_views(self, X: object, fit: _KernelFit) -> torch.Tensor:
        return self._check_fitted_views(X, fit)

    def transform(self, X: torch.Tensor) -> torch.Tensor:
        """Projects views onto the kernel eigenspace.

        Args:
            X: (P, N) or (P, C, H, W) views with N = ``n_features_in_``, of the fitted dtype.

        Returns:
            (P, k) coordinates ``(k(X, X_fit_) − kernel_mean_) @ coefficients_``.

        Raises:
            NotFittedError: before ``fit``.
            TypeError: ``X`` is not a float tensor of the fitted dtype.
            ValueError: ``X`` has the wrong number of features or non-finite values.
        """
        fit = self._fitted("transform")
        x = self._check_views(X, fit)
        with torch.no_grad():
            rows = self._kernel(x, fit.vectors, fit.gamma, "X, X_fit_")
            return (rows - fit.kernel_mean) @ fit.coefficients

    def nystrom_error(self, X: torch.Tensor) -> float:
        """Relative Frobenius error ‖K − K̃‖_F / ‖K‖_F of the Nyström kernel on views ``X``.

        K = k(X, X) is the exact (uncentred) kernel matrix, K̃ = C W⁺ Cᵀ with C = k(X, L):
        this needs the P×P matrix, so use it on a subset that fits in memory.

        Args:
            X: (P, N) or (P, C, H, W) views of the fitted dtype.

        Raises:
            NotFittedError: before ``fit``.
            ValueError: fitted without ``nystrom``, or bad ``X``.
        """
        fit = self._fitted("nystrom_error")
        if fit.w_inv_sqrt is None:
            raise ValueError("nystrom_error needs a Nyström fit: construct with nystrom=m")
        x = self._check_views(X, fit)
        with torch.no_grad():
            exact = self._kernel(x, x, fit.gamma, "X, X").double()
            phi = self._kernel(x, fit.vectors, fit.gamma, "X, L").double() @ fit.w_inv_sqrt.double()
            return float(torch.linalg.norm(exact - phi @ phi.T) / torch.linalg.norm(exact))

    def to_module(self, unit_norm: bool | None = None) -> KernelProjection:
        """Returns the frozen ``KernelProjection`` (copies of the fitted tensors).

        Args:
            unit_norm: whether the module divides each input view by its L2 norm first;
                None (the default) means as fitted, as in :meth:`Eigenspace.to_module`:
                this estimator fits the rows as given, so None is False.

        Raises:
            NotFittedError: before ``fit``.
            TypeError: the kernel is a callable (not exportable nor serialisable).
        """
        fit = self._fitted("to_module")
        if not isinstance(self.kernel, str):
            raise TypeError(
                f"to_module needs a named kernel, one of {KERNELS}: a callable kernel cannot be "
                "exported to ONNX nor saved in a state_dict (use transform instead)"
            )
        return KernelProjection.from_tensors(
            fit.vectors,
            fit.coefficients,
            fit.kernel_mean,
            kernel=self.kernel,
            gamma=fit.gamma,
            degree=self.degree,
            coef0=self.coef0,
            eigenvalues=fit.eigenvalues,
            image_shape=fit.image_shape,
            unit_norm=False if unit_norm is None else unit_norm,  # as fitted: the rows as given
        )
