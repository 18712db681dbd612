"""An eigenspace merged block by block, in memory bounded by one block and its own state.

The views arrive once, block by block (one object's synthesized gallery, say), and are
not kept. The model after P views is the mean μ, an orthonormal basis U (N × r) and the
eigenvalues s (r,) of the centred scatter matrix it represents, U diag(s) Uᵀ. Merging a
block X (B × N) with mean μ_b is the merge of two eigenspace models (Hall, Marshall and
Martin, "Merging and splitting eigenspace models", 2000; Levy and Lindenbaum's sequential
Karhunen–Loève update, 2000) in one identity of scatter matrices:

    S' = U diag(s) Uᵀ + Xcᵀ Xc + c cᵀ,   c = √(P B / (P + B)) (μ_b − μ),

so S' = M Mᵀ with M = [U diag(√s), Xcᵀ, c] (N × (r + B + 1)), whose eigenpairs come from
the small Gram matrix K = Mᵀ M (U being orthonormal, its leading block is diag(s)
exactly): K = V Λ Vᵀ, U' = M V Λ^(−1/2). Nothing N × N and nothing P × P is ever formed:
memory is the block, the basis and a few (r + B)-sized matrices, whatever P.

The model keeps at most ``max_rank`` eigenpairs. Up to that rank the merge is exact (the
eigenspace equals :class:`~torch_eigview.decomposition.eigenspace.Eigenspace`'s on the
stacked views up to rounding); past it the smallest eigenpairs of each merge are dropped.
A dropped part is a positive semidefinite matrix whose norm is the largest eigenvalue
dropped, so by Weyl's inequality every kept eigenvalue is low by at most the sum, over the
merges, of the largest eigenvalue each dropped: ``truncation_bound_``, reported with the
fit (0 when nothing was dropped).

With ``keep_codes=True`` the model also carries every view's coordinates in its basis,
rotated at each merge by the same small matrices (no product of size N): ``codes_`` are the
views' coordinates in the final components, exact below the rank cap.
"""

from __future__ import annotations

import math

import torch

from torch_eigview.check import check_float_tensor, check_int, check_magnitude, check_ndim
from torch_eigview.decomposition._fitted import DTYPES, FittedEigenspace
from torch_eigview.decomposition.linalg import EigenFit, centred_k, numerical_rank
from torch_eigview.errors import NotFittedError

__all__ = ["IncrementalEigenspace"]


class IncrementalEigenspace(FittedEigenspace):
    """Eigenspace of views merged block by block (``partial_fit``), each block seen once.

    Args:
        n_components: k (int) or an energy fraction in (0, 1) of the views seen.
        max_rank: the most eigenpairs the running model keeps, >= the int k: up to it every
            merge is exact; past it each merge drops its smallest eigenpairs, and
            ``truncation_bound_`` bounds how low that leaves the kept eigenvalues.
        keep_codes: also carry every view's coordinates (``codes_``), P × ``max_rank``
            numbers in memory.

    After a merge, ``mean_``, ``components_``, ``eigenvalues_`` and
    ``explained_variance_ratio_`` are those of
    :class:`~torch_eigview.decomposition.eigenspace.Eigenspace`; ``truncation_bound_``
    is the sum over the merges of the largest eigenvalue each dropped (every eigenvalue is
    at most this much below the exact eigenspace's; 0 when none was dropped), and
    ``discarded_energy_``, ``n_samples_seen_`` and ``codes_`` are below.

    Example:
        >>> x = torch.rand(30, 1, 6, 6, dtype=torch.float64)
        >>> inc = IncrementalEigenspace(4)
        >>> for block in x.split(7):
        ...     _ = inc.partial_fit(block)
        >>> from torch_eigview.decomposition import Eigenspace
        >>> exact = Eigenspace(4).fit(x)
        >>> bool(torch.allclose(inc.eigenvalues_, exact.eigenvalues_)), inc.truncation_bound_
        (True, 0.0)
    """

    _FIT_CALLS = "partial_fit or fit"

    def __init__(
        self, n_components: int | float = 15, *, max_rank: int = 512, keep_codes: bool = False
    ) -> None:
        super().__init__(n_components)
        self.max_rank = max_rank
        self.keep_codes = keep_codes

    def _validate_params(self) -> None:
        """Checks the arguments, stored as given (scikit-learn's habit); every merge calls it."""
        super()._validate_params()
        max_rank = check_int(self.max_rank, "max_rank", minimum=1)
        if isinstance(self.n_components, int) and self.n_components > max_rank:
            raise ValueError(f"max_rank={max_rank} must be at least n_components={self.n_components}")
        if not isinstance(self.keep_codes, bool):
            raise TypeError(
                f"keep_codes must be a bool, got {type(self.keep_codes).__name__} {self.keep_codes!r}"
            )

    def __repr__(self) -> str:
        return f"IncrementalEigenspace(n_components={self.n_components!r}, max_rank={self.max_rank!r})"

    # ------------------------------------------------------------------ the running model
    def _reset(self) -> None:
        self._mean: torch.Tensor | None = None  # (N,) float64
        self._basis: torch.Tensor | None = None  # (N, r) in the data's dtype, orthonormal columns
        self._eigvals = torch.zeros(0, dtype=torch.float64)  # (r,) of the scatter
        self._codes: list[torch.Tensor] = []  # per block (B, r) in the current basis, the data's dtype
        self._n = 0
        self._total = 0.0  # the trace of the scatter of every view seen
        self._uncentred = 0.0  # ‖X‖², for the rank tolerance of the centring
        self.truncation_bound_ = 0.0
        self._dropped = 0.0
        self._shape: tuple[int, int, int] | None = None
        self._dtype: torch.dtype | None = None

    def partial_fit(self, X: torch.Tensor) -> IncrementalEigenspace:
        """Merges a block of views into the model.

        Args:
            X: (B, N) or (B, C, H, W) views, B >= 1, the dtype and size of the first block's.

        Returns:
            self, its eigenspace that of every view merged so far.

        Raises:
            TypeError, ValueError: a bad ``n_components``, ``max_rank`` or block; the
                message names it.
        """
        self._validate_params()
        if not hasattr(self, "_n"):
            self._reset()
        x, shape = blocks_of_views(X, self._shape, self._dtype)
        if self._mean is not None and x.shape[1] != self._mean.shape[0]:
            raise ValueError(
                f"X must hold views of the first block's N={self._mean.shape[0]} values, got shape {tuple(X.shape)}"
            )
        self._shape, self._dtype = shape, x.dtype
        with torch.no_grad():
            self._merge(x, int(self.max_rank))
        self._stale = True  # the record is made when first read (a merge may leave rank 0)
        return self

    def _fitted(self, what: str) -> EigenFit:
        if getattr(self, "_n", 0) == 0:
            return super()._fitted(what)
        if getattr(self, "_stale", False):
            with torch.no_grad():
                self._state = self._record()
            self._stale = False
        return super()._fitted(what)

    def _merge(self, x: torch.Tensor, max_rank: int) -> None:
        """The merge of the module's docstring, with ``x`` (B, N) in the data's dtype: the
        products of size N run in it (float32 data: the speed of a float32 GEMM, rounding
        far below a truncation's), the small matrices, the mean and the eigenproblem in
        float64."""
        mean_b, squares = _float64_sums(x)
        xc = x - mean_b.to(x.dtype)
        gram = (xc @ xc.T).double()  # (B, B)
        self._uncentred += squares
        rot_new, shift, n_old, n_new = self._merge_rows(
            xc, mean_b, x.shape[0], gram, float(gram.diagonal().sum()), max_rank
        )
        if self.keep_codes:
            # The block: U'ᵀ(x − μ') = Xc U' + U'ᵀ(μ_b − μ'), μ_b − μ' = (P/P') d.
            self._codes.append((rot_new if shift is None else rot_new + (n_old / n_new) * shift).to(x.dtype))

    def merge(self, other: IncrementalEigenspace) -> IncrementalEigenspace:
        """Merges the model of other views into this one (Hall, Marshall and Martin's merge
        of two eigenspace models): the result is the model of both sets of views, exact
        below ``max_rank`` as a block merge is. ``other``'s rows enter as
        ``diag(√s_o) U_oᵀ``, whose scatter is ``other``'s; with ``keep_codes`` its views'
        coordinates follow, after this model's own. This is how models fitted apart (on
        the ranks of a process group, say) become one.

        Args:
            other: a fitted ``IncrementalEigenspace`` of views of the same size and dtype
                (with ``keep_codes`` when this one keeps codes).

        Returns:
            self.

        Raises:
            TypeError, ValueError: ``other`` is not a fitted model of the same size and dtype.
        """
        if not isinstance(other, IncrementalEigenspace):
            raise TypeError(f"other must be an IncrementalEigenspace, got {type(other).__name__}")
        if getattr(other, "_n", 0) == 0 or other._basis is None or other._mean is None:
            raise ValueError("other must be fitted (partial_fit or fit) before it is merged")
        if self.keep_codes and not other.keep_codes:
            raise ValueError(
                "other must keep its codes (keep_codes=True) to be merged into a model that keeps codes"
            )
        max_rank = check_int(self.max_rank, "max_rank", minimum=1)
        if not hasattr(self, "_n") or self._n == 0:
            self._reset()
            self._copy_state(other)
            return self
        assert self._mean is not None and self._basis is not None
        if other._mean.shape != self._mean.shape or other._dtype != self._dtype:
            raise ValueError(
                f"other must hold views of N={self._mean.shape[0]} values of {self._dtype}, got "
                f"N={other._mean.shape[0]} of {other._dtype}"
            )
        # In float64 whatever the data's dtype: a model's rows diag(√s) Uᵀ carry its basis'
        # rounding, which a float32 merge would compound (codes 1e-4 off where a block
        # merge's are 1e-7); models merge rarely (once per rank), so the cost is small.
        w = other._basis.dtype
        basis_o = other._basis.double()
        rows = other._eigvals.clamp_min(0).sqrt()[:, None] * basis_o.T  # (r_o, N)
        self._uncentred += other._uncentred
        self.truncation_bound_ += other.truncation_bound_
        self._dropped += other._dropped
        self._basis = self._basis.double()
        self._codes = [a.double() for a in self._codes]
        with torch.no_grad():
            rot_rows, shift, n_old, n_new = self._merge_rows(
                rows, other._mean, other._n, rows @ rows.T, other._total, max_rank
            )
            assert self._basis is not None
            if self.keep_codes:
                assert shift is not None
                # U_oᵀ U' = diag(1/√s_o) (Y U'), from the small matrices as the block merge's
                # rotations are (the product with U_o itself would carry its rounding).
                turn = (
                    rot_rows
                    / other._eigvals.clamp_min(0).sqrt().clamp_min(torch.finfo(torch.float64).tiny)[:, None]
                )
                move = (n_old / n_new) * shift
                self._codes += [torch.addmm(move, a.double(), turn) for a in other._codes]
        self._basis = self._basis.to(w)
        self._codes = [a.to(w) for a in self._codes]
        self._stale = True
        return self

    def report_as(self, dtype: torch.dtype) -> IncrementalEigenspace:
        """Reports the fitted record (``mean_``, ``components_``, ``eigenvalues_``,
        ``codes_``, the layer) in ``dtype`` (float32 or float64), whatever the dtype the
        views were merged in: float32 views merged in float64, for models merged across a
        process group's ranks, whose float32 bases would round their codes 1e-4 apart."""
        if dtype not in DTYPES:
            raise TypeError(f"dtype must be torch.float32 or torch.float64, got {dtype}")
        self._report = dtype
        self._stale = True
        return self

    def _copy_state(self, other: IncrementalEigenspace) -> None:
        assert other._mean is not None and other._basis is not None
        self._mean, self._basis, self._eigvals = (
            other._mean.clone(),
            other._basis.clone(),
            other._eigvals.clone(),
        )
        self._codes = [c.clone() for c in other._codes] if self.keep_codes else []
        self._n, self._total, self._uncentred = other._n, other._total, other._uncentred
        self.truncation_bound_, self._dropped = other.truncation_bound_, other._dropped
        self._shape, self._dtype = other._shape, other._dtype
        self._stale = True

    def _merge_rows(
        self,
        xc: torch.Tensor,
        mean_b: torch.Tensor,
        b: int,
        gram: torch.Tensor,
        block_total: float,
        max_rank: int,
    ) -> tuple[torch.Tensor, torch.Tensor | None, int, int]:
        """Merges rows ``xc`` (R, N) whose scatter ``xcᵀ xc`` is that of ``b`` views of mean
        ``mean_b`` (a block's centred views, R = b; or a model's ``diag(√s) Uᵀ``), ``gram``
        their (R, R) ``xc xcᵀ`` in float64 and ``block_total`` their scatter's trace. The
        earlier views' codes are rotated here; returns ``(Xc U', U'ᵀ d or None, P, P')`` for
        the caller to place the new views' codes."""
        w = xc.dtype
        rows = xc.shape[0]
        if self._mean is None or self._basis is None:
            k_small = gram
            n_old, root, weight = 0, torch.zeros(0, dtype=torch.float64), 0.0
            p = u_c = g = c = None
            cc = 0.0
            r = 0
        else:
            n_old, basis, s = self._n, self._basis, self._eigvals
            r = s.shape[0]
            weight = math.sqrt(n_old * b / (n_old + b))
            c = (weight * (mean_b - self._mean)).to(w)
            root = s.clamp_min(0).sqrt()
            p = (basis.T @ xc.T).double()  # (r, R)
            u_c = (basis.T @ c).double()  # (r,)
            g = (xc @ c).double()  # (R,)
            cc = float(c.double() @ c.double())
            k_mat = torch.zeros(r + rows + 1, r + rows + 1, dtype=torch.float64)
            k_mat[:r, :r] = torch.diag(s)
            k_mat[:r, r : r + rows] = root[:, None] * p
            k_mat[:r, -1] = root * u_c
            k_mat[r : r + rows, r : r + rows] = gram
            k_mat[r : r + rows, -1] = g
            k_mat[-1, -1] = cc
            k_small = k_mat.triu() + torch.triu(k_mat, 1).T
        lam, vec = torch.linalg.eigh(k_small)
        lam, vec = lam.flip(0), vec.flip(1)
        n_new = n_old + b
        self._total += block_total + cc
        dtype = self._dtype or torch.float64
        rank = numerical_rank(lam, n_new, xc.shape[1], dtype, self._uncentred)
        keep = min(max_rank, rank)
        keep_vec = vec[:, :keep]  # none for identical views so far: nothing to span yet
        if rank > keep:  # the cap, not rounding, drops eigenpairs: Weyl's bound grows
            self.truncation_bound_ += float(lam[keep])
            self._dropped += float(lam[keep:rank].sum())
        lam_k = lam[:keep]
        inv = lam_k.rsqrt() if keep else lam_k
        # U' = M V Λ^(-1/2), M = [U diag(√s), Xcᵀ, c] (the first block: M = Xcᵀ).
        shift = None
        if self._basis is None:
            new_basis = (xc.T @ keep_vec.to(w)).mul_(inv.to(w))
            rot_new = (gram @ keep_vec) * inv  # (R, r'): the rows' own coordinates
        else:
            assert p is not None and u_c is not None and g is not None and c is not None
            v_old, v_blk, v_c = keep_vec[:r], keep_vec[r : r + rows], keep_vec[r + rows]
            # One (N, r') buffer, the products accumulated into it: a sum of three products
            # would hold four such temporaries at once (N r' floats each, the merge's peak).
            new_basis = torch.addmm(c[:, None] * v_c.to(w), self._basis, (root[:, None] * v_old).to(w))
            new_basis.addmm_(xc.T, v_blk.to(w)).mul_(inv.to(w))
            # Uᵀ-free rotations: U'ᵀ U, U'ᵀ d and U'ᵀ Xcᵀ from the small matrices alone.
            rot_old = (v_old * root[:, None] + p @ v_blk + u_c[:, None] * v_c) * inv  # (r, r'): Uᵀ U'
            shift = ((root * u_c) @ v_old + g @ v_blk + cc * v_c) * inv / weight  # (r',): U'ᵀ d
            rot_new = ((p.T * root) @ v_old + gram @ v_blk + g[:, None] * v_c) * inv  # (R, r'): Xc U'
            if self.keep_codes:
                # Old views: x ≈ μ + U a, so a' = U'ᵀ(U a + μ − μ') = (Uᵀ U')ᵀ a − (B/P') U'ᵀ d.
                # One (P, r) product a merge, in the data's dtype: P · r numbers kept, and the
                # rotations' rounding far below a truncation's.
                rot, move = rot_old.to(w), ((b / n_new) * shift).to(w)
                for i, a in enumerate(self._codes):  # a block at a time: one block more held
                    self._codes[i] = torch.addmm(-move, a, rot)
        self._basis, self._eigvals = new_basis, lam_k
        self._mean = mean_b if self._mean is None else self._mean + (b / n_new) * (mean_b - self._mean)
        self._n = n_new
        return rot_new, shift, n_old, n_new

    def _record(self) -> EigenFit:
        assert self._mean is not None and self._basis is not None and self._dtype is not None
        dtype = getattr(self, "_report", None) or self._dtype
        k = centred_k(
            self.n_components,
            self._eigvals,
            torch.tensor(self._total, dtype=torch.float64),
            self._mean,
            self._n,
            dtype,
            "the views merged",
        )
        components = self._basis[:, :k].T
        fit = EigenFit.from_eigenpairs(
            self._mean,
            components,
            self._eigvals[:k],
            torch.tensor(self._total, dtype=torch.float64),
            self._n,
            self._shape,
            dtype,
        )
        self._signs = (fit.components.double() * components.double()).sum(1).sign()  # peak_signs flips
        return fit

    @property
    def n_samples_seen_(self) -> int:
        """P, the views merged so far."""
        self._fitted("n_samples_seen_")
        return self._n

    @property
    def discarded_energy_(self) -> float:
        """Σ of the dropped eigenvalues as a fraction of the trace (0 when none was)."""
        self._fitted("discarded_energy_")
        return self._dropped / self._total if self._total > 0 else 0.0

    @property
    def codes_(self) -> torch.Tensor:
        """(P, k) coordinates of the views merged, in ``components_`` (``keep_codes``)."""
        fit = self._fitted("codes_")
        if not self.keep_codes:
            raise NotFittedError("codes_ needs keep_codes=True before the first partial_fit")
        k = fit.n_components
        codes = torch.cat(self._codes)[:, :k] * self._signs
        return codes.to(fit.dtype)

    def fit(self, X: object) -> IncrementalEigenspace:
        """Forgets any earlier merge and merges ``X``: a (P, N) or (P, C, H, W) tensor, in
        blocks of ``max_rank`` views, or an iterable of such blocks.

        Raises:
            ValueError: no view.
        """
        self._validate_params()
        self._reset()
        self._state = None
        if isinstance(X, torch.Tensor):
            blocks = list(X.split(check_int(self.max_rank, "max_rank", minimum=1)))
        else:
            blocks = list(X)  # type: ignore[call-overload]
        for block in blocks:
            self.partial_fit(block)
        if self._n == 0:
            raise ValueError("X must hold at least one view, got none")
        self._fitted("fit")  # the record, or the error of a gallery of rank 0, now
        return self


def _float64_sums(x: torch.Tensor) -> tuple[torch.Tensor, float]:
    """The (N,) mean of (B, N) rows and the sum of their squares, accumulated in float64 a
    few rows at a time: ``x.mean(0, dtype=torch.float64)`` converts all of ``x`` first (twice
    its float32 size, more than the rest of a merge holds), these a chunk of about 2 MiB."""
    total = torch.zeros(x.shape[1], dtype=torch.float64, device=x.device)
    squares = 0.0
    for chunk in x.split(max(1, (1 << 18) // max(x.shape[1], 1))):
        wide = chunk.double()
        total += wide.sum(0)
        squares += float(wide.square().sum())
    return total / x.shape[0], squares


def blocks_of_views(
    X: object, shape: tuple[int, int, int] | None, dtype: torch.dtype | None
) -> tuple[torch.Tensor, tuple[int, int, int] | None]:
    """A block as (B, N) rows and its (C, H, W), checked against the earlier blocks'."""
    x = check_float_tensor(X, "X")
    if x.dtype not in DTYPES:
        raise TypeError(f"X must have dtype float32 or float64, got {x.dtype}")
    check_ndim(x, "X", (2, 4), "(B, N) or (B, C, H, W)")
    if x.shape[0] < 1 or math.prod(x.shape[1:]) == 0:
        raise ValueError(f"X must hold at least one view of at least one value, got shape {tuple(x.shape)}")
    if dtype is not None and x.dtype != dtype:
        raise TypeError(f"X must have the first block's dtype {dtype}, got {x.dtype}")
    block_shape = (x.shape[1], x.shape[2], x.shape[3]) if x.ndim == 4 else None
    flat = x.detach().reshape(x.shape[0], -1)
    if shape is not None and (block_shape not in (None, shape) or flat.shape[1] != math.prod(shape)):
        raise ValueError(f"X must hold views of the first block's shape {shape}, got {tuple(x.shape[1:])}")
    check_magnitude(flat, "X", max(flat.shape))
    return flat, shape if shape is not None else block_shape
