"""The ``Eigenspace`` estimator: PCA of a set of views (Sec. 2 of the paper).

Convention: a data matrix ``X`` is (P, N), one row per view and N = C*H*W values per view
(row-major flatten of (C, H, W)); the paper writes its transpose, the views as columns.
The estimator centres the views, eigen-decomposes their scatter matrix, and keeps the
leading k eigenvectors; ``to_module`` hands them out as a frozen ``EigenProjection``.
"""

from __future__ import annotations

import contextlib
import itertools
import math
from dataclasses import dataclass

import numpy as np
import torch

from torch_eigview.check import (
    check_finite,
    check_float_tensor,
    check_image_shape,
    check_n_components,
    check_ndim,
)
from torch_eigview.errors import NotFittedError
from torch_eigview.nn.projection import EigenProjection

__all__ = ["Eigenspace"]

_SOLVERS = ("auto", "gram", "covariance", "svd")
_DTYPES = (torch.float32, torch.float64)  # what torch.linalg decomposes


@dataclass(frozen=True)
class _Fit:
    mean: torch.Tensor  # (N,)
    components: torch.Tensor  # (k, N)
    eigenvalues: torch.Tensor  # (k,)
    ratio: torch.Tensor  # (k,)
    n_samples: int
    image_shape: tuple[int, int, int] | None


def _check_sparse(t: object, name: str, layout: str) -> torch.Tensor:
    if not isinstance(t, torch.Tensor) or t.layout not in (torch.sparse_coo, torch.sparse_csr):
        got = t.layout if isinstance(t, torch.Tensor) else type(t).__name__
        raise TypeError(f"{name} must be a sparse COO or CSR tensor {layout}, got {got}")
    if t.ndim != 2:
        raise ValueError(f"{name} must have shape {layout}, got shape {tuple(t.shape)}")
    if t.dtype not in _DTYPES:
        raise TypeError(f"{name} must have dtype float32 or float64, got {t.dtype}")
    check_finite(t.coalesce().values() if t.layout == torch.sparse_coo else t.values(), name)
    return t


def _flip_signs(components: torch.Tensor) -> torch.Tensor:
    """Makes each row's entry of largest magnitude positive (sklearn's ``svd_flip`` on Vᵀ)."""
    peak = components.gather(1, components.abs().argmax(dim=1, keepdim=True))
    return components * torch.where(peak < 0, -1.0, 1.0).to(components.dtype)


def _gram(xc: torch.Tensor, panels: int = 4) -> torch.Tensor:
    """Xc Xcᵀ (P, P) from its upper block triangle, mirrored: a syrk-like product.

    torch has no syrk; computing only the row panels' blocks right of the diagonal does
    (panels + 1) / (2 panels) of the GEMM's 2·N·P² flops (10/16 for 4 panels) in large GEMMs,
    and the result is exactly symmetric, as eigh wants. Small P: one GEMM.
    """
    n_views = xc.shape[0]
    if n_views < 512:
        return xc @ xc.T
    edges = [n_views * i // panels for i in range(panels + 1)]
    out = xc.new_empty(n_views, n_views)
    for lo, hi in itertools.pairwise(edges):
        block = xc[lo:hi] @ xc[lo:].T  # (hi - lo, P - lo)
        out[lo:hi, lo:] = block
        out[hi:, lo:hi] = block[:, hi - lo :].T
    return out


_BLAS_CONTROLLER: list[object] = []  # a cached threadpoolctl.ThreadpoolController, when installed


def _single_threaded_blas() -> contextlib.AbstractContextManager[object]:
    """SciPy's BLAS (OpenBLAS) limited to one thread, when threadpoolctl is installed.

    Between torch's thread pool (busy right before and after, GEMMs) and OpenBLAS's own,
    two pools contend for the cores: on 2 cores the COIL-20 fit spends ~40 ms more in the
    eigh and the components product than with OpenBLAS on one thread (spinning workers).
    """
    if not _BLAS_CONTROLLER:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - a dependency; kept optional for vendored installs
            _BLAS_CONTROLLER.append(None)
        else:
            _BLAS_CONTROLLER.append(ThreadpoolController())
    controller = _BLAS_CONTROLLER[0]
    if controller is None:
        return contextlib.nullcontext()
    limited: contextlib.AbstractContextManager[object] = controller.limit(  # type: ignore[attr-defined]
        limits=1, user_api="blas"
    )
    return limited


def _rank_tolerance(
    largest: float, uncentred: float, n_views: int, n_features: int, dtype: torch.dtype
) -> float:
    """Eigenvalues of the centred scatter at or below this are rounding noise.

    Two sources, in the data's ``dtype`` whatever precision the eigensolver ran in: the
    Gram/scatter product, whose length-n dot products round to ~√n·eps relative to the
    largest eigenvalue ``largest``; and the centring, which leaves each entry of X − μ off
    by ~eps·|x|, noise of energy up to eps²·‖X‖² (``uncentred`` = ‖X‖², before centring).
    The second alone is the largest eigenvalue of identical views whose mean does not
    come out exact, which a bound relative to ``largest`` cannot catch.
    """
    root, eps = math.sqrt(max(n_views, n_features)), torch.finfo(dtype).eps
    return max(largest * root * eps, uncentred * root * eps * eps)


def _eigh_descending(scatter: torch.Tensor, top: int | None) -> tuple[torch.Tensor, torch.Tensor]:
    """Eigenpairs of a symmetric float64 matrix by decreasing eigenvalue; the leading ``top``
    only (or all when None).

    For a few leading pairs of a large matrix on the CPU: ARPACK's implicitly restarted
    Lanczos (SciPy's ``eigsh``, ``tol=0``: converged to machine precision, a fixed
    pseudo-random start, deterministic). On image data, whose spectrum decays, it needs a
    few hundred products with the P×P matrix: 0.02 s against 0.07 s for LAPACK's
    ``dsyevr`` on an index subset at P = 820, k = 15 (COIL-20), eigenpairs equal to 1e-15.
    On a flat spectrum (white noise) it is up to 1.5x slower than ``dsyevr``, and where it
    does not converge (or cannot start: a zero matrix) ``dsyevr`` (MRRR, backward
    stable) takes over. The rank (eigenvalues
    above a tolerance) is still exact from the leading ``top``: when it is below ``top`` the
    remaining eigenvalues, smaller, are below the tolerance too.
    """
    n = scatter.shape[0]
    if top is not None and scatter.device.type == "cpu" and n >= 256 and top <= n // 4:
        from scipy.linalg import eigh  # scikit-image depends on SciPy
        from scipy.sparse.linalg import ArpackNoConvergence, eigsh

        a = scatter.numpy()
        with _single_threaded_blas() if n <= 2048 else contextlib.nullcontext():
            # Not the ones vector: it spans the null space of a centred Gram matrix.
            v0 = np.random.default_rng(0).standard_normal(n)
            found = None
            if a.any():  # ARPACK cannot start on a zero matrix (identical views)
                try:
                    found = eigsh(a, k=top, which="LA", tol=0, v0=v0, ncv=min(n, max(2 * top + 1, 48)))
                except ArpackNoConvergence:
                    pass
            w, v = found or eigh(a, subset_by_index=[n - top, n - 1], driver="evr", check_finite=False)
        order = np.argsort(w)[::-1].copy()
        return torch.from_numpy(w[order]), torch.from_numpy(np.ascontiguousarray(v[:, order]))
    w, v = torch.linalg.eigh(scatter)
    return w.flip(0), v.flip(1)


def _views_from_sparse(g: torch.Tensor, c: torch.Tensor, block_size: int) -> torch.Tensor:
    """(P, N) rows of the views A = G·C (Eq. 6), built ``block_size`` columns of C at a time."""
    n_inner, n_views = c.shape
    # Cᵀ coalesced is sorted by column of C, so each block of columns is one contiguous slice.
    c_t = c.to_sparse_coo().t().coalesce()
    cols, rows = c_t.indices()
    values = c_t.values()
    edges = torch.searchsorted(cols, torch.arange(0, n_views + block_size, block_size, device=cols.device))
    bounds = edges.tolist()
    # TODO(streaming issue): accumulate the mean and the P×P Gram matrix block by block
    # instead of holding X, so that memory is bounded by the block size.
    x = torch.empty(n_views, g.shape[0], dtype=g.dtype, device=g.device)
    for i, start in enumerate(range(0, n_views, block_size)):
        stop = min(start + block_size, n_views)
        lo, hi = bounds[i], bounds[i + 1]
        block = torch.zeros(n_inner, stop - start, dtype=c.dtype, device=c.device)
        block[rows[lo:hi], cols[lo:hi] - start] = values[lo:hi]
        x[start:stop] = torch.sparse.mm(g, block).T
    return x


class Eigenspace:
    """Eigenspace (PCA) of P views, fitted like a scikit-learn estimator.

    ``eigenvalues_`` are the eigenvalues λ of the centred scatter matrix Xcᵀ Xc (the paper's
    λ), i.e. scikit-learn's ``explained_variance_ * (P - 1)``; ``explained_variance_`` is
    λ / (P - 1). Eigenvalues are sorted in descending order, those at or below the rank
    tolerance ``max(λ) * sqrt(max(P, N)) * eps(dtype)`` are dropped, and each component's entry of
    largest magnitude is made positive, so results do not depend on the solver's signs.

    Args:
        n_components: k as an int >= 1, or a float in (0, 1): the energy fraction, giving
            the smallest k with sum_{i<=k} λ_i / sum_i λ_i >= fraction (the paper uses 0.99).
        solver: "gram" eigen-decomposes the P×P Gram matrix Xc Xcᵀ and maps its eigenvectors
            V to components (Xcᵀ V) / sqrt(λ); "covariance" the N×N matrix Xcᵀ Xc; "svd" runs
            ``torch.linalg.svd`` on Xc; "auto" picks "gram" when N > P, else "covariance".

    Raises:
        TypeError: ``n_components`` is not a number (bool included) or ``solver`` not a str.
        ValueError: ``n_components`` or ``solver`` is out of range.

    Example:
        >>> X = torch.randn(20, 64, dtype=torch.float64)
        >>> Eigenspace(n_components=5).fit(X).transform(X).shape
        torch.Size([20, 5])
    """

    def __init__(self, n_components: int | float = 15, *, solver: str = "auto") -> None:
        self.n_components = check_n_components(n_components)
        if not isinstance(solver, str):
            raise TypeError(f"solver must be a str, one of {_SOLVERS}, got {type(solver).__name__}")
        if solver not in _SOLVERS:
            raise ValueError(f"solver={solver!r} must be one of {_SOLVERS}")
        self.solver = solver
        self._state: _Fit | None = None

    def __repr__(self) -> str:
        return f"Eigenspace(n_components={self.n_components!r}, solver={self.solver!r})"

    # ------------------------------------------------------------------ fitted attributes
    def _fitted(self, what: str) -> _Fit:
        if self._state is None:
            raise NotFittedError(f"this Eigenspace is not fitted yet: call fit or fit_sparse before {what}")
        return self._state

    @property
    def mean_(self) -> torch.Tensor:
        """(N,) the mean view."""
        return self._fitted("mean_").mean

    @property
    def components_(self) -> torch.Tensor:
        """(k, N) orthonormal eigenvectors, one per row, by decreasing eigenvalue."""
        return self._fitted("components_").components

    @property
    def eigenvalues_(self) -> torch.Tensor:
        """(k,) eigenvalues λ of Xcᵀ Xc, descending (sklearn's ``explained_variance_ * (P - 1)``)."""
        return self._fitted("eigenvalues_").eigenvalues

    @property
    def explained_variance_(self) -> torch.Tensor:
        """(k,) variance along each component, λ / (P - 1) as in scikit-learn."""
        fit = self._fitted("explained_variance_")
        return fit.eigenvalues / (fit.n_samples - 1)

    @property
    def explained_variance_ratio_(self) -> torch.Tensor:
        """(k,) fraction of the total variance (over all eigenvalues) along each component."""
        return self._fitted("explained_variance_ratio_").ratio

    @property
    def n_components_(self) -> int:
        """k, the number of components kept."""
        return self._fitted("n_components_").components.shape[0]

    @property
    def n_samples_(self) -> int:
        """P, the number of views fitted."""
        return self._fitted("n_samples_").n_samples

    @property
    def n_features_in_(self) -> int:
        """N, the number of values per view."""
        return self._fitted("n_features_in_").mean.shape[0]

    @property
    def image_shape_(self) -> tuple[int, int, int] | None:
        """(C, H, W) when fitted on (P, C, H, W) views or given to ``fit_sparse``, else None."""
        return self._fitted("image_shape_").image_shape

    # ------------------------------------------------------------------ fitting
    def fit(self, X: torch.Tensor) -> Eigenspace:
        """Fits the eigenspace of the views ``X``.

        Args:
            X: (P, N) or (P, C, H, W) float32/float64 views, P >= 2, finite.

        Returns:
            self, fitted.

        Raises:
            TypeError: ``X`` is not a float32/float64 tensor.
            ValueError: bad shape, P < 2, non-finite values, or an int ``n_components``
                larger than the rank of the centred views.
        """
        x, image_shape = self._check_views_to_fit(X)
        with torch.no_grad():
            self._fit_views(x, image_shape, "X")
        return self

    def fit_transform(self, X: torch.Tensor) -> torch.Tensor:
        """Fits on ``X`` (P, N) or (P, C, H, W) and returns its (P, k) coordinates."""
        x, image_shape = self._check_views_to_fit(X)
        with torch.no_grad():
            xc = self._fit_views(x, image_shape, "X")
            return xc @ self.components_.T

    def fit_sparse(
        self,
        G: torch.Tensor,
        C: torch.Tensor,
        image_shape: tuple[int, int, int] | None = None,
        block_size: int = 256,
    ) -> Eigenspace:
        """Fits on the views A = G·C of Eq. 6 without the caller materialising them.

        The P views are the columns of A; they are formed ``block_size`` columns of C at a
        time (each block of C densified, then ``torch.sparse.mm``).

        Args:
            G: (N, M) sparse COO or CSR tensor.
            C: (M, P) sparse COO or CSR tensor of G's dtype, P >= 2.
            image_shape: optional (C, H, W) of a view, with C*H*W = N.
            block_size: columns of C per block, >= 1.

        Returns:
            self, fitted.

        Raises:
            TypeError: G or C is not a float32/float64 sparse COO/CSR tensor, or their
                dtypes differ; ``block_size`` is not an int.
            ValueError: the inner sizes differ, P < 2, non-finite values, a bad
                ``image_shape`` or ``block_size``, or ``n_components`` exceeds the rank.
        """
        _check_sparse(G, "G", "(N, M)")
        _check_sparse(C, "C", "(M, P)")
        if C.dtype != G.dtype:
            raise TypeError(f"C must have the dtype of G ({G.dtype}), got {C.dtype}")
        if G.shape[1] != C.shape[0]:
            raise ValueError(
                f"G.shape[1] must equal C.shape[0] (the inner size M of G·C), "
                f"got G of shape {tuple(G.shape)} and C of shape {tuple(C.shape)}"
            )
        if C.shape[1] < 2:
            raise ValueError(f"C must have at least 2 columns (views), got shape {tuple(C.shape)}")
        if isinstance(block_size, bool) or not isinstance(block_size, int):
            raise TypeError(f"block_size must be an int, got {type(block_size).__name__}")
        if block_size < 1:
            raise ValueError(f"block_size={block_size} must be >= 1")
        shape = check_image_shape(image_shape, G.shape[0], "image_shape")
        with torch.no_grad():
            self._fit_views(_views_from_sparse(G, C, block_size), shape, "G·C")
        return self

    @staticmethod
    def _check_views_to_fit(X: object) -> tuple[torch.Tensor, tuple[int, int, int] | None]:
        x = check_float_tensor(X, "X")
        if x.dtype not in _DTYPES:
            raise TypeError(f"X must have dtype float32 or float64, got {x.dtype}")
        check_ndim(x, "X", (2, 4), "(P, N) or (P, C, H, W)")
        if x.shape[0] < 2:
            raise ValueError(f"X must hold at least 2 views (rows), got P={x.shape[0]}")
        # NaN/inf anywhere makes the sum non-finite; a finite sum proves every value finite
        # and is ~10x cheaper than an elementwise mask (0.2 s on the 820 x 16,384 COIL data).
        # A non-finite sum may also be an overflow of finite values: the exact check decides.
        if x.numel() and not bool(torch.isfinite(x.sum())):
            check_finite(x, "X")
        image_shape = (x.shape[1], x.shape[2], x.shape[3]) if x.ndim == 4 else None
        return x.detach().reshape(x.shape[0], -1), image_shape

    def _fit_views(
        self, x: torch.Tensor, image_shape: tuple[int, int, int] | None, name: str
    ) -> torch.Tensor:
        """Fits on validated (P, N) views and returns the centred views Xc (P, N)."""
        n_views, n_features = x.shape
        dtype = x.dtype
        mean = x.mean(dim=0)
        xc = x - mean
        solver = self.solver
        if solver == "auto":
            solver = "gram" if n_features > n_views else "covariance"

        # The small symmetric eigenproblem runs in float64 (eigh is cheap at that size and
        # float32 eigenvectors of a nearly degenerate spectrum are poor); products stay in
        # the input dtype. ``basis`` maps to components once k is known.
        if solver == "svd":
            _, s, basis = torch.linalg.svd(xc, full_matrices=False)
            eigvals = s.double().square()
        else:
            scatter = (_gram(xc) if solver == "gram" else xc.T @ xc).double()
            top = self.n_components if isinstance(self.n_components, int) else None
            eigvals, basis = _eigh_descending(scatter, top)

        # The eigenvalues sum to trace(Xc Xcᵀ) = ||Xc||², the total over all eigenvalues
        # (the trace also when only the leading ones were computed).
        total = eigvals.sum() if solver == "svd" else scatter.diagonal().sum()
        uncentred = float(total) + n_views * float(mean.double().square().sum())
        tol = _rank_tolerance(float(eigvals[0]), uncentred, n_views, n_features, dtype)
        rank = int((eigvals > tol).sum())
        if rank == 0:
            raise ValueError(f"{name} has rank 0 after centring: all {n_views} views are identical")
        eigvals = eigvals[:rank]
        if isinstance(self.n_components, int):
            k = self.n_components
            if k > rank:
                raise ValueError(
                    f"n_components={k} exceeds the rank of {name} ({rank}: {n_views} views, centred)"
                )
        else:
            cumulative = torch.cumsum(eigvals, 0) / total
            k = min(int((cumulative < self.n_components).sum()) + 1, rank)

        eigvals = eigvals[:k]
        if solver == "svd":
            components = basis[:k]
        elif solver == "gram":
            components = (basis[:, :k].T.to(dtype) @ xc) / eigvals.sqrt().to(dtype)[:, None]
        else:
            components = basis[:, :k].T.to(dtype)
        self._state = _Fit(
            mean=mean,
            components=_flip_signs(components.contiguous()),
            eigenvalues=eigvals.to(dtype),
            ratio=(eigvals / total).to(dtype),
            n_samples=n_views,
            image_shape=image_shape,
        )
        return xc

    # ------------------------------------------------------------------ inference
    def transform(self, X: torch.Tensor) -> torch.Tensor:
        """Projects views onto the eigenspace.

        Args:
            X: (P, N) or (P, C, H, W) views with N = ``n_features_in_``, of the fitted dtype.

        Returns:
            (P, k) coordinates ``(X - mean_) @ components_.T``.

        Raises:
            NotFittedError: before ``fit``.
            TypeError: ``X`` is not a float tensor of the fitted dtype.
            ValueError: ``X`` has the wrong number of features.
        """
        fit = self._fitted("transform")
        x = check_float_tensor(X, "X")
        check_ndim(x, "X", (2, 4), "(P, N) or (P, C, H, W)")
        n_features = fit.mean.shape[0]
        if math.prod(x.shape[1:]) != n_features:
            expected = f"(P, {n_features})"
            if fit.image_shape is not None:
                expected += f" or (P, {', '.join(map(str, fit.image_shape))})"
            raise ValueError(f"X must have shape {expected} as fitted, got shape {tuple(x.shape)}")
        if x.dtype != fit.mean.dtype:
            raise TypeError(f"X must have the fitted dtype {fit.mean.dtype}, got {x.dtype}")
        return (x.reshape(x.shape[0], -1) - fit.mean) @ fit.components.T

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
        k = fit.components.shape[0]
        if z.ndim != 2 or z.shape[1] != k:
            raise ValueError(f"Z must have shape (P, {k}), got shape {tuple(z.shape)}")
        if z.dtype != fit.mean.dtype:
            raise TypeError(f"Z must have the fitted dtype {fit.mean.dtype}, got {z.dtype}")
        return z @ fit.components + fit.mean

    def to_module(self) -> EigenProjection:
        """Returns the frozen ``EigenProjection`` (copies of mean, components, eigenvalues)."""
        fit = self._fitted("to_module")
        return EigenProjection(fit.mean, fit.components, fit.eigenvalues, fit.image_shape)
