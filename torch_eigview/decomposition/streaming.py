"""Eigenspaces from a stream of view blocks, never holding the whole (P, N) data matrix.

Views arrive block by block (typically one object's views per block) from a *re-generable*
source: a callable that returns a fresh iterable of blocks each time it is called (the
blocks are synthesized again, or read again from disk), a sequence of tensors, or one
tensor split into row blocks. Every pass over the source must yield the same views.

Three solvers (``solver=``), all bounded in memory (``"auto"`` takes ``"subspace"`` where
:class:`~torch_eigview.decomposition.eigenspace.Eigenspace`'s "auto" would, else ``"exact"``;
the default is ``"exact"``: a pass over a stream costs more than the products alone, so a
subspace iteration stopped for slow convergence costs more here than in memory):

- ``"exact"``: pass 1 folds the views into their mean (float64 sums). When N <= P the
  N×N scatter matrix Σ_b (B_b − μ)ᵀ(B_b − μ) is accumulated in one more pass, blocks
  gathered into chunks of up to N/2 views (memory N² plus a chunk). Otherwise the P×P
  Gram matrix Xc Xcᵀ is needed, whose cross-block entries need both blocks: each pass
  holds a *panel* of consecutive blocks (at most ``max_views`` views) and multiplies the
  later blocks against it, gathered into chunks of a few hundred views
  (``torch_eigview._tuning.CHUNK_VIEWS``; fewer when ``max_views`` is smaller; one block
  at least), so ⌈P / max_views⌉ passes fill the upper block triangle (memory P² plus a
  panel plus a chunk plus a block). A last pass maps the leading eigenvectors V of the
  Gram matrix to components Λ^(−1/2) Vᵀ Xc = Σ_b Λ^(−1/2) V_bᵀ (B_b − μ), accumulated into
  (k, N). The result is
  the :class:`~torch_eigview.decomposition.eigenspace.Eigenspace` of the stacked views.
- ``"randomized"``: a randomized range finder (Halko, Martinsson and Tropp 2011, Alg. 4.4
  with power iterations) on Xcᵀ: Y = Xcᵀ Ω (N × l, l = k + oversample, 10 by default) is
  accumulated as Σ_b (B_b − μ)ᵀ Ω_b, each power iteration Y ← Xcᵀ (Xc Q) is one pass
  (per block Z_b = (B_b − μ) Q, Y += (B_b − μ)ᵀ Z_b), and a last pass forms Z = Xc Q (P × l), whose
  SVD gives the components. Memory: a block plus N·l plus P·l; 3 + ``n_iter`` passes.
- ``"subspace"``: after the mean, block subspace iteration until the k leading eigenpairs
  converge (:func:`~torch_eigview.decomposition.subspace.subspace_eigenpairs`, an int k):
  each iteration is one pass, W_b = (B_b − μ) V and Y += (B_b − μ)ᵀ W_b, blocks gathered
  into chunks as above. Memory: a chunk plus N·l plus P·l (l = k + oversample, 35 by
  default). Where it does not converge within half what the exact products cost,
  ``"exact"`` takes over.

``fit_transform`` projects the views block by block in one pass more. The linear algebra
is :mod:`torch_eigview.decomposition.linalg`'s, shared with ``Eigenspace``.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Sequence

import torch

import torch_eigview._tuning as _tuning
from torch_eigview.check import check_int
from torch_eigview.decomposition._fitted import FittedEigenspace
from torch_eigview.decomposition._stream import BlockSource, Stream, blocks_of, stream_mean
from torch_eigview.decomposition.eigenspace import exact_solver, pick_solver
from torch_eigview.decomposition.linalg import (
    EigenFit,
    centred_k,
    check_oversample,
    gram,
    leading_eigenpairs,
    oversample_for,
    randomized_passes,
    sketch_components,
    sketch_matrix,
)
from torch_eigview.decomposition.subspace import leading_by_subspace

__all__ = ["BlockSource", "StreamingEigenspace", "blocks_of"]

_SOLVERS = ("auto", "exact", "subspace", "randomized")
_NAME = "the streamed views"  # the fitted views, as the errors name them
# The chunk size the fits read from _tuning at call time, kept under its old name for
# the benchmarks' memory model (benchmarks/_fit_case.py imports it from here).
CHUNK_VIEWS = _tuning.CHUNK_VIEWS


class StreamingEigenspace(FittedEigenspace):
    """The eigenspace (PCA) of views read from a stream of blocks, never all held at once.

    The fitted attributes, ``transform``, ``inverse_transform`` and ``to_module`` are those
    of :class:`~torch_eigview.decomposition.eigenspace.Eigenspace`, which the exact method
    equals on the stacked views (the subspace solver to its tolerance); ``solver_`` is the
    solver that ran ("exact" where the subspace iteration handed over to it), and
    ``n_passes_`` the passes over the source.

    Args:
        n_components: k (int >= 1) or an energy fraction in (0, 1).
        solver: ``"exact"`` (mean, then the N×N scatter or the P×P Gram matrix by panels;
            equals ``Eigenspace`` on the stacked views), ``"subspace"`` (subspace iteration
            converged to the k leading eigenpairs, an int k), ``"auto"`` (``"subspace"``
            where ``Eigenspace``'s "auto" takes it, else ``"exact"``) or ``"randomized"``
            (range finder, a fixed number of passes).
        max_views: the most views the exact Gram path holds at once (a panel), >= 1.
        oversample: the vectors beyond k of the iterative methods' blocks, l = k +
            ``oversample``: an int >= 0 for both, or "auto", each method's own:
            :data:`~torch_eigview.decomposition.subspace.SUBSPACE_OVERSAMPLE` (35) for
            "subspace", whose wider block converges in fewer passes, and
            :data:`~torch_eigview.decomposition.linalg.RANDOMIZED_OVERSAMPLE` (10) for
            "randomized", whose passes are fixed and whose extra directions buy accuracy.
        n_iter: power iterations of the randomized method.
        seed: seed of the randomized method's test matrix Ω (P, l), drawn in float64.
        method: deprecated, the old name of ``solver`` (``Eigenspace``'s name for the same
            choice); it warns and sets ``solver``.

    The arguments are stored as given and checked when a fit starts (scikit-learn's habit).

    Example:
        >>> X = torch.randn(30, 64, dtype=torch.float64)
        >>> StreamingEigenspace(5).fit(blocks_of(X, 8)).components_.shape
        torch.Size([5, 64])
    """

    _FIT_CALLS = "fit or fit_transform"

    def __init__(
        self,
        n_components: int | float = 15,
        *,
        solver: str = "exact",
        max_views: int = 4096,
        oversample: int | str = "auto",
        n_iter: int = 2,
        seed: int = 0,
        method: str | None = None,
    ) -> None:
        super().__init__(n_components)
        if method is not None:
            warnings.warn(
                "StreamingEigenspace(method=...) is deprecated: the argument is named solver, as "
                "Eigenspace's; give solver=...",
                DeprecationWarning,
                stacklevel=2,
            )
            if solver != "exact":
                raise TypeError(f"give solver={solver!r} or the deprecated method={method!r}, not both")
            solver = method
        self.solver = solver
        self.max_views = max_views
        self.oversample = oversample
        self.n_iter = n_iter
        self.seed = seed
        self.n_passes_ = 0
        self.solver_: str | None = None  # None until a fit here (or a fit from elsewhere)

    def _validate_params(self) -> None:
        super()._validate_params()
        if not isinstance(self.solver, str) or self.solver not in _SOLVERS:
            raise ValueError(f"solver={self.solver!r} must be one of {_SOLVERS}")
        check_int(self.max_views, "max_views", 1)
        check_oversample(self.oversample)
        check_int(self.n_iter, "n_iter", 0)
        # Checked before the first pass, not when the randomized solver draws Ω after it.
        check_int(self.seed, "seed", -(2**63), 2**64 - 1)

    @property
    def method(self) -> str:
        """Deprecated: ``solver``."""
        warnings.warn(
            "StreamingEigenspace.method is deprecated: read solver", DeprecationWarning, stacklevel=2
        )
        return self.solver

    @property
    def method_(self) -> str | None:
        """Deprecated: ``solver_``."""
        warnings.warn(
            "StreamingEigenspace.method_ is deprecated: read solver_", DeprecationWarning, stacklevel=2
        )
        return self.solver_

    def __repr__(self) -> str:
        return f"StreamingEigenspace(n_components={self.n_components!r}, solver={self.solver!r})"

    def fit(self, X: torch.Tensor | BlockSource | Sequence[torch.Tensor]) -> StreamingEigenspace:
        """Fits on the views of a re-generable block source.

        Args:
            X: a callable returning a fresh iterable of (P_b, N) or (P_b, C, H, W) blocks on
                each call, a sequence of such blocks, or one (P, ...) tensor (read in blocks
                of 256 views). Blocks of 0 rows are skipped; P >= 2 in all.

        Returns:
            self, fitted; ``n_passes_`` counts the passes over the source.

        Raises:
            TypeError: a block is not a float32/float64 tensor, or the dtypes differ.
            ValueError: blocks of different view shapes, non-finite values, P < 2, a source
                that does not repeat itself, or ``n_components`` above the rank.
        """
        self._fit_stream(Stream(X))
        return self

    def fit_transform(self, X: torch.Tensor | BlockSource | Sequence[torch.Tensor]) -> torch.Tensor:
        """Fits on the views of ``X`` as :meth:`fit`, then projects them in one more pass.

        The views are projected block by block, so only the (P, k) coordinates are held;
        ``n_passes_`` counts the fit's passes and this one.

        Args:
            X: the block source, as for :meth:`fit`.

        Returns:
            (P, k) coordinates ``(X - mean_) @ components_.T``, views in the source's order.

        Raises:
            TypeError, ValueError: as :meth:`fit`.
        """
        stream = Stream(X)
        fit = self._fit_stream(stream)
        with torch.no_grad():
            z = torch.cat([self._project(b, fit) for b in stream])
        stream.check_result(z, "the coordinates")
        self.n_passes_ += 1
        return z

    def _fit_stream(self, stream: Stream) -> EigenFit:
        self._validate_params()
        with torch.no_grad():
            mean64 = stream_mean(stream)
            assert stream.n_views is not None and stream.dtype is not None
            if stream.n_views < 2:
                raise ValueError(f"blocks must hold at least 2 views in all, got P={stream.n_views}")
            method = self.solver
            if method in ("auto", "subspace"):
                oversample = oversample_for(self.oversample, "subspace")
                method = pick_solver(
                    self.n_components, method, stream.n_views, mean64.numel(), "solver", oversample
                )
            fit = self._subspace(stream, mean64) if method == "subspace" else None
            if fit is None and method == "randomized":
                fit = self._randomized(stream, mean64)
            elif fit is None:  # exact, or the subspace iteration did not converge
                gram_path = exact_solver(stream.n_views, mean64.numel()) == "gram"
                exact = self._exact_gram if gram_path else self._exact_covariance
                passes = self.n_passes_ - 1 if method == "subspace" else 0  # its mean pass is shared
                fit = exact(stream, mean64)
                self.n_passes_ += passes
                method = "exact"
            self.solver_ = method
        self._state = fit
        return fit

    # ------------------------------------------------------------------ exact
    @staticmethod
    def _record(
        stream: Stream, mean64: torch.Tensor, comps: torch.Tensor, eigvals: torch.Tensor, total: torch.Tensor
    ) -> EigenFit:
        """The fit from (k, N) components, their (k,) eigenvalues and the () trace."""
        assert stream.dtype is not None and stream.n_views is not None
        return EigenFit.from_eigenpairs(
            mean64, comps, eigvals, total, stream.n_views, stream.image_shape, stream.dtype
        )

    def _leading(
        self, scatter: torch.Tensor, stream: Stream, mean64: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        assert stream.dtype is not None and stream.n_views is not None
        stream.check_result(scatter, "the scatter or Gram matrix")
        return leading_eigenpairs(scatter, self.n_components, mean64, stream.n_views, stream.dtype, _NAME)

    def _exact_covariance(self, stream: Stream, mean64: torch.Tensor) -> EigenFit:
        mean = mean64.to(stream.dtype)
        n = mean.numel()
        scatter = torch.zeros(n, n, dtype=torch.float64, device=mean.device)
        # Blocks are gathered into chunks of up to N/2 views (a quarter of the scatter's bytes):
        # each chunk's product writes and adds a whole N×N matrix, so a chunk of one 41-view
        # block would pay N² memory traffic for a rank-41 update; N/2 views make that traffic
        # a small share of the chunk's 2·N²·(N/2) flops.
        self._centred_chunks(stream, mean, lambda _, c: scatter.add_(c.T @ c), max(1, n // 2))
        self.n_passes_ = 2
        eigvals, basis, total = self._leading(scatter, stream, mean64)
        return self._record(stream, mean64, basis.T, eigvals, total)

    def _exact_gram(self, stream: Stream, mean64: torch.Tensor) -> EigenFit:
        assert stream.n_views is not None
        mean = mean64.to(stream.dtype)
        p = stream.n_views
        matrix = torch.zeros(p, p, dtype=torch.float64, device=mean.device)
        panels = _panels(stream.block_rows, self.max_views)
        for lo, hi in panels:
            # The panel's blocks are centred straight into one buffer (no list + cat, which
            # would hold the panel twice at its peak); the later blocks are centred into a chunk
            # of up to _tuning.CHUNK_VIEWS views (and max_views), multiplied against the panel
            # when full: a few large GEMMs instead of one thin GEMM per object's block.
            panel = torch.empty(hi - lo, mean.numel(), dtype=mean.dtype, device=mean.device)
            chunks = _Chunks(
                mean, min(_tuning.CHUNK_VIEWS, self.max_views), functools.partial(_cross, matrix, panel, lo)
            )
            start = 0
            for b in stream:
                stop = start + b.shape[0]
                if lo <= start < hi:
                    torch.sub(b, mean, out=panel[start - lo : stop - lo])
                    if stop == hi:
                        matrix[lo:hi, lo:hi] = gram(panel).double()
                elif start >= hi:
                    chunks.add(start, b)
                start = stop
            chunks.close()
            del panel, chunks
        eigvals, basis, total = self._leading(matrix, stream, mean64)
        # Components Λ^(−1/2) Vᵀ Xc, one block of Xc at a time; the products in the data's
        # dtype as Eigenspace does, the sum in float64.
        comp = torch.zeros(eigvals.numel(), mean.numel(), dtype=torch.float64, device=mean.device)
        start = 0
        for b in stream:
            stop = start + b.shape[0]
            comp += (basis[start:stop].T.to(b.dtype) @ (b - mean)).double()
            start = stop
        stream.check_result(comp, "the components")
        self.n_passes_ = 2 + len(panels)
        return self._record(stream, mean64, comp / eigvals.sqrt()[:, None], eigvals, total)

    # ------------------------------------------------------------------ subspace
    def _subspace(self, stream: Stream, mean64: torch.Tensor) -> EigenFit | None:
        """The fit by subspace iteration, one pass per iteration, or None where it does not
        converge within the budget (the exact path takes over)."""
        assert stream.n_views is not None and stream.dtype is not None
        mean = mean64.to(stream.dtype)
        p, n = stream.n_views, mean.numel()
        k = self.n_components
        assert isinstance(k, int), "pick_solver admits subspace for an int k only"
        self.n_passes_ = 1  # the mean's
        # ‖Xc‖² by rows (as Eigenspace), read in the first iteration's pass.
        norms = mean64.new_zeros(p)
        norms_read = False

        def products(v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            nonlocal norms_read
            w = mean.new_empty(p, v.shape[1])
            y = torch.zeros(n, v.shape[1], dtype=torch.float64, device=mean.device)
            first = not norms_read

            def emit(start: int, chunk: torch.Tensor) -> None:
                part = torch.matmul(chunk, v, out=w[start : start + chunk.shape[0]])
                y.add_((chunk.T @ part).double())
                if first:
                    norms[start : start + chunk.shape[0]] = torch.linalg.vector_norm(chunk, dim=1).double()

            self._centred_chunks(stream, mean, emit)
            stream.check_result(w, "the products Xc V")
            norms_read = True
            self.n_passes_ += 1
            return w, y

        oversample = oversample_for(self.oversample, "subspace")
        found = leading_by_subspace(products, k, p, n, stream.dtype, mean.device, oversample)
        if found is None:
            return None
        eigvals, components = found
        total = norms.square().sum()
        k = centred_k(k, eigvals, total, mean64, p, stream.dtype, _NAME)
        return self._record(stream, mean64, components[:k], eigvals[:k], total)

    @staticmethod
    def _centred_chunks(
        stream: Stream,
        mean: torch.Tensor,
        emit: Callable[[int, torch.Tensor], object],
        rows: int | None = None,
    ) -> None:
        """One pass: every block centred, gathered into chunks of up to ``rows`` views
        (default ``_tuning.CHUNK_VIEWS``), each handed to ``emit(first view, chunk)``."""
        chunks = _Chunks(mean, _tuning.CHUNK_VIEWS if rows is None else rows, emit)
        start = 0
        for b in stream:
            chunks.add(start, b)
            start += b.shape[0]
        chunks.close()

    # ------------------------------------------------------------------ randomized
    def _randomized(self, stream: Stream, mean64: torch.Tensor) -> EigenFit:
        assert stream.n_views is not None and stream.dtype is not None
        p, n = stream.n_views, mean64.numel()
        oversample = oversample_for(self.oversample, "randomized")
        omega = sketch_matrix(self.n_components, oversample, p, n, self.seed, mean64.device)
        q, z, total = randomized_passes(stream, mean64, omega, self.n_iter, lambda t: t, row_offset=0)
        stream.check_result(z, "the sketch Xc Q")
        self.n_passes_ = 3 + self.n_iter
        eigvals, components = sketch_components(
            q, z, total, self.n_components, mean64, p, stream.dtype, _NAME
        )
        return self._record(stream, mean64, components, eigvals, total)


def _panels(block_rows: list[int], max_views: int) -> list[tuple[int, int]]:
    """Runs (first view, end) of whole consecutive blocks of at most ``max_views`` views (one block at least)."""
    panels: list[tuple[int, int]] = []
    lo = hi = 0
    for rows in block_rows:
        if hi > lo and hi + rows - lo > max_views:
            panels.append((lo, hi))
            lo = hi
        hi += rows
    panels.append((lo, hi))
    return panels


class _Chunks:
    """Centres consecutive blocks into one buffer of up to ``rows`` views (one block at
    least) and hands each full buffer on, ``emit(first view, (rows, N) chunk)``: a few large
    GEMMs instead of one thin GEMM per block."""

    def __init__(self, mean: torch.Tensor, rows: int, emit: Callable[[int, torch.Tensor], object]) -> None:
        self.mean, self.rows, self.emit = mean, rows, emit
        self.buffer = mean.new_empty(0, mean.numel())
        self.fill = self.start = 0

    def add(self, start: int, block: torch.Tensor) -> None:
        """Adds the block of views ``start..``; blocks must come in order, without gaps."""
        rows = block.shape[0]
        if self.fill and self.fill + rows > self.buffer.shape[0]:
            self.close()
        if self.fill == 0:
            self.start = start
            if rows > self.buffer.shape[0]:
                self.buffer = self.mean.new_empty(max(rows, self.rows), self.mean.numel())
        torch.sub(block, self.mean, out=self.buffer[self.fill : self.fill + rows])
        self.fill += rows

    def close(self) -> None:
        """Hands on what the buffer holds."""
        if self.fill:
            self.emit(self.start, self.buffer[: self.fill])
            self.fill = 0


def _cross(gram: torch.Tensor, panel: torch.Tensor, lo: int, start: int, chunk: torch.Tensor) -> None:
    """Writes the Gram blocks of a panel (views lo..) and a later chunk (views start..), both centred."""
    cross = (panel @ chunk.T).double()
    gram[lo : lo + panel.shape[0], start : start + chunk.shape[0]] = cross
    gram[start : start + chunk.shape[0], lo : lo + panel.shape[0]] = cross.T
