"""The ``Eigenspace`` estimator: PCA of a set of views (Sec. 2 of the paper).

Convention: a data matrix ``X`` is (P, N), one row per view and N = C*H*W values per view
(row-major flatten of (C, H, W)); the paper writes its transpose, the views as columns.
The estimator centres the views, eigen-decomposes their scatter matrix, and keeps the
leading k eigenvectors; ``to_module`` hands them out as a frozen ``EigenProjection``.
"""

from __future__ import annotations

import torch

from torch_eigview.check import check_choice, check_finite, check_image_shape, check_int, check_magnitude
from torch_eigview.decomposition._fitted import DTYPES, FittedEigenspace, views_to_fit
from torch_eigview.decomposition.linalg import (
    EigenFit,
    centred_k,
    check_oversample,
    gram,
    leading_eigenpairs,
    oversample_for,
)
from torch_eigview.decomposition.subspace import SUBSPACE_OVERSAMPLE, leading_by_subspace

__all__ = ["SUBSPACE_MIN", "Eigenspace", "exact_solver", "pick_solver"]

_SOLVERS = ("auto", "gram", "covariance", "svd", "subspace")

#: "auto" takes "subspace" for an int k once P and N are both at least this. The Gram
#: matrix by panels costs about 1.25·P²·N flops against 4·P·N·l per iteration (l = k + 35
#: = 50 at k = 15), so at this size the iteration's budget, half the exact cost, is about
#: 12 iterations, and an iteration stopped at its third (a spectrum without a gap) adds
#: about an eighth to the exact cost. Below it the budget shrinks with P (about 6
#: iterations at P = 2,048 when N > P), too few for a turntable gallery to converge in: COIL-20 galleries converge in 6 to 7 iterations (the full-circle gallery,
#: 7,200 × 16,384: 6), while 100 random smooth textures (4,100 × 49,152) would need about
#: 20 and are stopped at the third.
SUBSPACE_MIN = 4096


def exact_solver(n_views: int, n_features: int) -> str:
    """ "gram" when N > P, else "covariance": the smaller of the two products."""
    return "gram" if n_features > n_views else "covariance"


def pick_solver(
    n_components: int | float,
    solver: str,
    n_views: int,
    n_features: int,
    name: str = "solver",
    oversample: int = SUBSPACE_OVERSAMPLE,
) -> str:
    """The solver that runs for P × N views: ``solver``, or the one "auto" picks; ``name``
    is the argument that chose it, for the message. "auto" picks "subspace" for an int
    k when P and N are both at least :data:`SUBSPACE_MIN` and the block of k +
    ``oversample`` vectors fits in both, else :func:`exact_solver`'s.

    Raises:
        ValueError: "subspace" with a fractional ``n_components``.
    """
    if solver == "subspace" and not isinstance(n_components, int):
        raise ValueError(f"{name}='subspace' needs an int n_components (k), got {n_components!r}")
    if solver != "auto":
        return solver
    small = min(n_views, n_features)
    if isinstance(n_components, int) and small >= SUBSPACE_MIN and n_components + oversample <= small:
        return "subspace"
    return exact_solver(n_views, n_features)


def _check_sparse(t: object, name: str, layout: str) -> torch.Tensor:
    if not isinstance(t, torch.Tensor) or t.layout not in (torch.sparse_coo, torch.sparse_csr):
        got = t.layout if isinstance(t, torch.Tensor) else type(t).__name__
        raise TypeError(f"{name} must be a sparse COO or CSR tensor {layout}, got {got}")
    if t.ndim != 2:
        raise ValueError(f"{name} must have shape {layout}, got shape {tuple(t.shape)}")
    if t.dtype not in DTYPES:
        raise TypeError(f"{name} must have dtype float32 or float64, got {t.dtype}")
    check_finite(t.coalesce().values() if t.layout == torch.sparse_coo else t.values(), name)
    return t


def _views_from_sparse(g: torch.Tensor, c: torch.Tensor, block_size: int) -> torch.Tensor:
    """(P, N) rows of the views A = G·C (Eq. 6), built ``block_size`` columns of C at a time."""
    n_inner, n_views = c.shape
    # Cᵀ coalesced is sorted by column of C, so each block of columns is one contiguous slice.
    c_t = c.to_sparse_coo().t().coalesce()
    cols, rows = c_t.indices()
    values = c_t.values()
    edges = torch.searchsorted(cols, torch.arange(0, n_views + block_size, block_size, device=cols.device))
    bounds = edges.tolist()
    x = torch.empty(n_views, g.shape[0], dtype=g.dtype, device=g.device)
    for i, start in enumerate(range(0, n_views, block_size)):
        stop = min(start + block_size, n_views)
        lo, hi = bounds[i], bounds[i + 1]
        block = torch.zeros(n_inner, stop - start, dtype=c.dtype, device=c.device)
        block[rows[lo:hi], cols[lo:hi] - start] = values[lo:hi]
        x[start:stop] = torch.sparse.mm(g, block).T
    return x


class Eigenspace(FittedEigenspace):
    """Eigenspace (PCA) of P views, fitted like a scikit-learn estimator.

    ``eigenvalues_`` are the eigenvalues λ of the centred scatter matrix Xcᵀ Xc (the paper's
    λ), i.e. scikit-learn's ``explained_variance_ * (P - 1)``; ``explained_variance_`` is
    λ / (P - 1). Eigenvalues are sorted in descending order, those at or below the rank
    tolerance (:func:`~torch_eigview.decomposition.linalg.rank_tolerance`: the product's
    ``max(λ) * sqrt(max(P, N)) * eps(dtype)`` or the centring's rounding) are dropped, and
    each component's entry of largest magnitude is made positive, so results do not depend
    on the solver's signs. ``solver_`` is the solver that ran ("auto"'s choice, and "gram" or
    "covariance" where "subspace" handed over to it; None before a fit, and for a fit made
    elsewhere and handed in with ``from_fit``).

    Args:
        n_components: k as an int >= 1, or a float in (0, 1): the energy fraction, giving
            the smallest k with sum_{i<=k} λ_i / sum_i λ_i >= fraction (the paper uses 0.99).
        solver: "gram" eigen-decomposes the P×P Gram matrix Xc Xcᵀ and maps its eigenvectors
            V to components (Xcᵀ V) / sqrt(λ); "covariance" the N×N matrix Xcᵀ Xc; "svd" runs
            ``torch.linalg.svd`` on Xc; "subspace" iterates a block of k + ``oversample``
            vectors (:func:`~torch_eigview.decomposition.subspace.subspace_eigenpairs`, an
            int ``n_components`` only) until the k leading eigenpairs converge, falling
            back to "gram" / "covariance" where they do not within half the products those
            cost; "auto" picks "subspace" for an int ``n_components`` when P and N are both
            at least :data:`SUBSPACE_MIN` (4096: below it the iterations the budget allows
            are too few for a turntable gallery) and the block fits in both, else "gram"
            when N > P, else "covariance" (the smaller of the two products).
        oversample: the vectors beyond k in the "subspace" solver's block, an int >= 0
            (at least 1 for the iteration to run; 0 leaves it to the exact path), or
            "auto": :data:`~torch_eigview.decomposition.subspace.SUBSPACE_OVERSAMPLE`
            (35). A wider block converges in fewer iterations, each reading the views
            twice. The other solvers do not use it.

    The arguments are stored as given and checked when a fit starts (scikit-learn's habit).

    Raises:
        TypeError: at fit, ``n_components`` is not a number (bool included), ``solver`` not
            a str or ``oversample`` neither "auto" nor an int.
        ValueError: at fit, ``n_components``, ``solver`` or ``oversample`` is out of range,
            or "subspace" with a fractional ``n_components``.

    Example:
        >>> X = torch.randn(20, 64, dtype=torch.float64)
        >>> Eigenspace(n_components=5).fit(X).transform(X).shape
        torch.Size([20, 5])
    """

    _FIT_CALLS = "fit or fit_sparse"

    def __init__(
        self, n_components: int | float = 15, *, solver: str = "auto", oversample: int | str = "auto"
    ) -> None:
        super().__init__(n_components)
        self.solver = solver
        self.oversample = oversample
        self.solver_: str | None = None  # None until a fit here (or a fit from elsewhere)

    def _validate_params(self) -> None:
        super()._validate_params()
        check_choice(self.solver, "solver", _SOLVERS)
        check_oversample(self.oversample)

    def __repr__(self) -> str:
        # scikit-learn's way: the parameters always shown, and oversample where it is set.
        extra = "" if self.oversample == "auto" else f", oversample={self.oversample!r}"
        return f"Eigenspace(n_components={self.n_components!r}, solver={self.solver!r}{extra})"

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
        self._validate_params()
        x, image_shape = views_to_fit(X)
        with torch.no_grad():
            self._fit_views(x, image_shape, "X")
        return self

    def fit_transform(self, X: torch.Tensor) -> torch.Tensor:
        """Fits on ``X`` (P, N) or (P, C, H, W) and returns its (P, k) coordinates."""
        self._validate_params()
        x, image_shape = views_to_fit(X)
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
        time (each block of C densified, then ``torch.sparse.mm``) into one (P, N) matrix.
        ``StreamingEigenspace`` fits from blocks without holding all the views.

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
        self._validate_params()
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
        block_size = check_int(block_size, "block_size", 1)
        shape = check_image_shape(image_shape, G.shape[0], "image_shape")
        with torch.no_grad():
            x = _views_from_sparse(G, C, block_size)
            check_magnitude(x, "G·C", max(x.shape))
            self._fit_views(x, shape, "G·C")
        return self

    def _fit_views(
        self, x: torch.Tensor, image_shape: tuple[int, int, int] | None, name: str
    ) -> torch.Tensor:
        """Fits on validated (P, N) views and returns the centred views Xc (P, N)."""
        n_views, n_features = x.shape
        dtype = x.dtype
        mean = x.mean(dim=0)
        xc = x - mean
        oversample = oversample_for(self.oversample, "subspace")
        solver = pick_solver(self.n_components, self.solver, n_views, n_features, oversample=oversample)
        if solver == "subspace":
            found = self._subspace(xc, mean, name, oversample)
            if found is not None:
                eigvals, components, total = found
                self._state = EigenFit.from_eigenpairs(
                    mean, components, eigvals, total, n_views, image_shape, dtype
                )
                self.solver_ = solver
                return xc
            solver = exact_solver(n_views, n_features)

        # The small symmetric eigenproblem runs in float64 (eigh is cheap at that size and
        # float32 eigenvectors of a nearly degenerate spectrum are poor); products stay in
        # the input dtype.
        if solver == "svd":
            _, s, basis = torch.linalg.svd(xc, full_matrices=False)
            eigvals = s.double().square()
            total = eigvals.sum()  # trace(Xc Xcᵀ) = ‖Xc‖², the sum of all eigenvalues
            k = centred_k(self.n_components, eigvals, total, mean, n_views, dtype, name)
            eigvals, components = eigvals[:k], basis[:k]
        else:
            scatter = (gram(xc) if solver == "gram" else xc.T @ xc).double()
            eigvals, basis, total = leading_eigenpairs(scatter, self.n_components, mean, n_views, dtype, name)
            components = basis.T.to(dtype)
            if solver == "gram":
                components = (components @ xc) / eigvals.sqrt().to(dtype)[:, None]
        self._state = EigenFit.from_eigenpairs(mean, components, eigvals, total, n_views, image_shape, dtype)
        self.solver_ = solver
        return xc

    def _subspace(
        self, xc: torch.Tensor, mean: torch.Tensor, name: str, oversample: int
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
        """Eigenvalues (k,), components (k, N) and trace of the centred (P, N) views ``xc``
        by subspace iteration with k + ``oversample`` vectors, or None where it did not
        converge (or there is no room for a vector beyond k): the exact path takes over."""
        n_views, n_features = xc.shape
        k = self.n_components
        assert isinstance(k, int), "pick_solver admits subspace for an int k only"

        def products(v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            w = xc @ v
            return w, xc.T @ w

        found = leading_by_subspace(products, k, n_views, n_features, xc.dtype, xc.device, oversample)
        if found is None:
            return None
        eigvals, components = found
        # trace(Xc Xcᵀ) = ‖Xc‖², the sum of all eigenvalues: row norms (one long float32 sum
        # over all P·N values drifts by percents), summed in float64.
        total = torch.linalg.vector_norm(xc, dim=1).double().square().sum()
        k = centred_k(k, eigvals, total, mean, n_views, xc.dtype, name)
        return eigvals[:k], components[:k], total
