"""Eigenspaces from a stream of view blocks, never holding the whole (P, N) data matrix.

Views arrive block by block (typically one object's views per block) from a *re-generable*
source: a callable that returns a fresh iterable of blocks each time it is called (the
blocks are synthesized again, or read again from disk), a sequence of tensors, or one
tensor split into row blocks. Every pass over the source must yield the same views.

Two methods, both bounded in memory:

- ``"exact"``: pass 1 folds the views into their mean (float64 sums). When N <= P the
  N×N scatter matrix Σ_b (B_b − μ)ᵀ(B_b − μ) is accumulated in one more pass, blocks
  gathered into chunks of up to N/2 views (memory N² plus a chunk). Otherwise the P×P Gram matrix Xc Xcᵀ is needed, whose cross-block entries
  need both blocks: each pass holds a *panel* of consecutive blocks (at most
  ``max_views`` views) and multiplies the later blocks against it, gathered into chunks
  of up to 256 views (fewer when ``max_views`` is smaller; one block at least), so
  ⌈P / max_views⌉ passes fill the upper block triangle (memory P² plus a panel plus a
  chunk plus a block). A last
  pass maps the leading eigenvectors V of the Gram matrix to components
  Λ^(−1/2) Vᵀ Xc = Σ_b Λ^(−1/2) V_bᵀ (B_b − μ), accumulated into (k, N). The result is
  the :class:`~torch_eigview.decomposition.eigenspace.Eigenspace` of the stacked views.
- ``"randomized"``: a randomized range finder (Halko, Martinsson and Tropp 2011, Alg. 4.4
  with power iterations) on Xcᵀ: Y = Xcᵀ Ω (N × l, l = k + oversample) is accumulated as
  Σ_b (B_b − μ)ᵀ Ω_b, each power iteration Y ← Xcᵀ (Xc Q) is one pass (per block
  Z_b = (B_b − μ) Q, Y += (B_b − μ)ᵀ Z_b), and a last pass forms Z = Xc Q (P × l), whose
  SVD gives the components. Memory: a block plus N·l plus P·l; 3 + ``n_iter`` passes.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable, Iterator, Sequence

import torch

from torch_eigview.check import check_finite, check_float_tensor, check_ndim
from torch_eigview.decomposition.eigenspace import (
    Eigenspace,
    _eigh_descending,
    _Fit,
    _flip_signs,
    _gram,
    _rank_tolerance,
)

__all__ = ["BlockSource", "StreamingEigenspace", "blocks_of"]

BlockSource = Callable[[], Iterable[torch.Tensor]]
"""A callable returning a fresh iterable of (P_b, N) or (P_b, C, H, W) view blocks."""

_METHODS = ("exact", "randomized")
CHUNK_VIEWS = 256  # views per cross-product GEMM of the exact Gram path


def blocks_of(x: torch.Tensor, block_size: int) -> BlockSource:
    """A re-generable source over the rows of an explicit (P, ...) tensor, ``block_size`` rows a block."""
    if isinstance(block_size, bool) or not isinstance(block_size, int):
        raise TypeError(f"block_size must be an int, got {type(block_size).__name__}")
    if block_size < 1:
        raise ValueError(f"block_size={block_size} must be >= 1")
    return lambda: (x[i : i + block_size] for i in range(0, x.shape[0], block_size))


class _Stream:
    """Validates the blocks of a source pass after pass: dtype, feature shape and P on every
    pass. Finiteness is checked by the first pass, :func:`_mean`, on each block's column
    sums (a NaN or infinity anywhere makes its column's sum non-finite); a later pass must
    repeat the first, and the fits check what they accumulate (:meth:`check_result`)
    rather than scan every block again: that scan was a quarter of an exact fit's time."""

    def __init__(self, source: object, name: str = "blocks") -> None:
        if isinstance(source, torch.Tensor):
            source = blocks_of(source, 256)
        elif isinstance(source, Sequence) and not isinstance(source, str):
            blocks = list(source)
            source = lambda: iter(blocks)  # noqa: E731
        if not callable(source):
            raise TypeError(
                f"{name} must be a callable returning an iterable of view blocks, a sequence of "
                f"tensors or a tensor, got {type(source).__name__}"
            )
        self.source: Callable[[], Iterable[object]] = source
        self.name = name
        self.dtype: torch.dtype | None = None
        self.device: torch.device | None = None
        self.feature_shape: tuple[int, ...] | None = None
        self.n_views: int | None = None
        self.block_rows: list[int] = []
        self.index = -1  # the source's index of the block last yielded

    def __iter__(self) -> Iterator[torch.Tensor]:
        rows: list[int] = []
        for i, block in enumerate(self.source()):
            what = f"{self.name}[{i}]"
            b = check_float_tensor(block, what)
            check_ndim(b, what, (2, 4), "(P_b, N) or (P_b, C, H, W)")
            if b.dtype not in (torch.float32, torch.float64):
                raise TypeError(f"{what} must have dtype float32 or float64, got {b.dtype}")
            if self.feature_shape is None:
                self.feature_shape, self.dtype, self.device = tuple(b.shape[1:]), b.dtype, b.device
            elif tuple(b.shape[1:]) != self.feature_shape:
                raise ValueError(
                    f"{what} must have shape (P_b, {', '.join(map(str, self.feature_shape))}) like the "
                    f"first block, got shape {tuple(b.shape)}"
                )
            elif b.dtype != self.dtype:
                raise TypeError(f"{what} must have the first block's dtype {self.dtype}, got {b.dtype}")
            if b.shape[0] == 0:
                continue
            rows.append(b.shape[0])
            self.index = i
            yield b.detach().reshape(b.shape[0], -1).to(self.device)
        if self.n_views is None:
            self.n_views, self.block_rows = sum(rows), rows
        elif rows != self.block_rows:
            raise ValueError(
                f"{self.name} is not re-generable: a later pass gave blocks of {rows[:8]}... rows, the "
                f"first {self.block_rows[:8]}... (a source must yield the same views on every call)"
            )

    def check_result(self, x: torch.Tensor, what: str) -> None:
        """Raises ValueError when a sum over later passes is not finite (the first pass was)."""
        if not bool(torch.isfinite(x).all()):
            raise ValueError(
                f"{self.name} gave non-finite values on a later pass ({what} came out non-finite) although the "
                "first pass was finite: either the source did not yield the same views on every call (it "
                "must), or the sums overflowed the blocks' dtype (values too large: rescale the views)"
            )

    @property
    def image_shape(self) -> tuple[int, int, int] | None:
        s = self.feature_shape
        return (s[0], s[1], s[2]) if s is not None and len(s) == 3 else None


def select_k(
    n_components: int | float, eigvals: torch.Tensor, total: torch.Tensor, name: str, n_views: int
) -> int:
    """k from leading eigenvalues (descending, above the rank tolerance), as ``Eigenspace`` picks it."""
    rank = eigvals.numel()
    if rank == 0:
        raise ValueError(f"{name} has rank 0 after centring: all {n_views} views are identical")
    if isinstance(n_components, int):
        if n_components > rank:
            raise ValueError(
                f"n_components={n_components} exceeds the rank of {name} ({rank}: {n_views} views, centred)"
            )
        return n_components
    cumulative = torch.cumsum(eigvals, 0) / total
    reached = int((cumulative < n_components).sum()) + 1
    return min(reached, rank)


def above_tolerance(
    eigvals: torch.Tensor, total: torch.Tensor, mean64: torch.Tensor, n_views: int, dtype: torch.dtype
) -> torch.Tensor:
    """The eigenvalues above ``Eigenspace``'s rank tolerance (``eigenspace._rank_tolerance``);
    ``total`` is the trace of the centred scatter, ``mean64`` the (N,) mean view."""
    uncentred = float(total) + n_views * float(mean64.double().square().sum())
    tol = _rank_tolerance(float(eigvals[0]), uncentred, n_views, mean64.numel(), dtype)
    return eigvals[eigvals > tol]


class StreamingEigenspace(Eigenspace):
    """An :class:`~torch_eigview.decomposition.eigenspace.Eigenspace` fitted from a stream of view blocks.

    The fitted attributes, ``transform`` and ``to_module`` are those of ``Eigenspace``.

    Args:
        n_components: k (int >= 1) or an energy fraction in (0, 1).
        method: ``"exact"`` (mean, then the N×N scatter or the P×P Gram matrix by panels;
            equals ``Eigenspace`` on the stacked views) or ``"randomized"`` (range finder).
        max_views: the most views the exact Gram path holds at once (a panel), >= 1.
        oversample: extra random directions of the randomized method (l = k + oversample).
        n_iter: power iterations of the randomized method.
        seed: seed of the randomized method's test matrix Ω (P, l), drawn in float64.

    Example:
        >>> X = torch.randn(30, 64, dtype=torch.float64)
        >>> StreamingEigenspace(5).fit(blocks_of(X, 8)).components_.shape
        torch.Size([5, 64])
    """

    def __init__(
        self,
        n_components: int | float = 15,
        *,
        method: str = "exact",
        max_views: int = 4096,
        oversample: int = 10,
        n_iter: int = 2,
        seed: int = 0,
    ) -> None:
        super().__init__(n_components)
        if not isinstance(method, str) or method not in _METHODS:
            raise ValueError(f"method={method!r} must be one of {_METHODS}")
        for name, value, low in (
            ("max_views", max_views, 1),
            ("oversample", oversample, 0),
            ("n_iter", n_iter, 0),
        ):
            if isinstance(value, bool) or not isinstance(value, int):
                raise TypeError(f"{name} must be an int, got {type(value).__name__}")
            if value < low:
                raise ValueError(f"{name}={value} must be >= {low}")
        self.method, self.max_views, self.oversample, self.n_iter, self.seed = (
            method,
            max_views,
            oversample,
            n_iter,
            seed,
        )
        self.n_passes_ = 0

    def __repr__(self) -> str:
        return f"StreamingEigenspace(n_components={self.n_components!r}, method={self.method!r})"

    def fit(self, X: torch.Tensor | BlockSource | Sequence[torch.Tensor]) -> StreamingEigenspace:
        """Fits on the views of a re-generable block source.

        Args:
            X: a callable returning a fresh iterable of (P_b, N) or (P_b, C, H, W) blocks on
                each call, a sequence of such blocks, or one (P, ...) tensor. Blocks of 0 rows
                are skipped; P >= 2 in all.

        Returns:
            self, fitted; ``n_passes_`` counts the passes over the source.

        Raises:
            TypeError: a block is not a float32/float64 tensor, or the dtypes differ.
            ValueError: blocks of different view shapes, non-finite values, P < 2, a source
                that does not repeat itself, or ``n_components`` above the rank.
        """
        stream = _Stream(X)
        with torch.no_grad():
            mean64 = _mean(stream)
            assert stream.n_views is not None and stream.dtype is not None
            if stream.n_views < 2:
                raise ValueError(f"blocks must hold at least 2 views in all, got P={stream.n_views}")
            if self.method == "randomized":
                self._state = self._randomized(stream, mean64)
            elif mean64.numel() <= stream.n_views:
                self._state = self._exact_covariance(stream, mean64)
            else:
                self._state = self._exact_gram(stream, mean64)
        return self

    # ------------------------------------------------------------------ exact
    def _finish(
        self,
        stream: _Stream,
        mean64: torch.Tensor,
        components: torch.Tensor,
        eigvals: torch.Tensor,
        total: torch.Tensor,
    ) -> _Fit:
        assert stream.dtype is not None and stream.n_views is not None
        dtype = stream.dtype
        return _Fit(
            mean=mean64.to(dtype),
            components=_flip_signs(components.to(dtype).contiguous()),
            eigenvalues=eigvals.to(dtype),
            ratio=(eigvals / total).to(dtype),
            n_samples=stream.n_views,
            image_shape=stream.image_shape,
        )

    def _leading(
        self, scatter: torch.Tensor, stream: _Stream, mean64: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, int]:
        assert stream.dtype is not None and stream.n_views is not None
        stream.check_result(scatter, "the scatter or Gram matrix")
        top = self.n_components if isinstance(self.n_components, int) else None
        eigvals, basis = _eigh_descending(scatter, top)
        total = scatter.diagonal().sum()
        kept = above_tolerance(eigvals, total, mean64, stream.n_views, stream.dtype)
        k = select_k(self.n_components, kept, total, "the streamed views", stream.n_views)
        return eigvals[:k], basis[:, :k], total, k

    def _exact_covariance(self, stream: _Stream, mean64: torch.Tensor) -> _Fit:
        mean = mean64.to(stream.dtype)
        n = mean.numel()
        scatter = torch.zeros(n, n, dtype=torch.float64, device=mean.device)
        # Blocks are gathered into chunks of up to N/2 views (a quarter of the scatter's bytes):
        # one 41-view block's product is a whole N×N matrix written and added for a rank-41
        # update, and 1,000 such were 13x slower than the explicit fit at N = 4096.
        chunks = _Chunks(mean, max(1, n // 2), lambda _, c: scatter.add_(c.T @ c))
        start = 0
        for b in stream:
            chunks.add(start, b)
            start += b.shape[0]
        chunks.close()
        self.n_passes_ = 2
        eigvals, basis, total, _ = self._leading(scatter, stream, mean64)
        return self._finish(stream, mean64, basis.T, eigvals, total)

    def _exact_gram(self, stream: _Stream, mean64: torch.Tensor) -> _Fit:
        assert stream.n_views is not None
        mean = mean64.to(stream.dtype)
        p = stream.n_views
        gram = torch.zeros(p, p, dtype=torch.float64, device=mean.device)
        # Panels: runs of whole consecutive blocks of at most max_views views (one block at least).
        panels: list[tuple[int, int]] = []
        lo = hi = 0
        for rows in stream.block_rows:
            if hi > lo and hi + rows - lo > self.max_views:
                panels.append((lo, hi))
                lo = hi
            hi += rows
        panels.append((lo, hi))
        for lo, hi in panels:
            # The panel's blocks are centred straight into one buffer (no list + cat, which
            # held the panel twice at its peak); the later blocks are centred into a chunk
            # of up to CHUNK_VIEWS views (and max_views), multiplied against the panel when full (a
            # GEMM with the 41 rows of one object runs at 2/3 of the speed of one with 256).
            panel = torch.empty(hi - lo, mean.numel(), dtype=mean.dtype, device=mean.device)
            chunks = _Chunks(
                mean, min(CHUNK_VIEWS, self.max_views), functools.partial(_cross, gram, panel, lo)
            )
            start = 0
            for b in stream:
                stop = start + b.shape[0]
                if lo <= start < hi:
                    torch.sub(b, mean, out=panel[start - lo : stop - lo])
                    if stop == hi:
                        gram[lo:hi, lo:hi] = _gram(panel).double()
                elif start >= hi:
                    chunks.add(start, b)
                start = stop
            chunks.close()
            del panel, chunks
        eigvals, basis, total, _ = self._leading(gram, stream, mean64)
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
        return self._finish(stream, mean64, comp / eigvals.sqrt()[:, None], eigvals, total)

    # ------------------------------------------------------------------ randomized
    def _randomized(self, stream: _Stream, mean64: torch.Tensor) -> _Fit:
        assert stream.n_views is not None and stream.dtype is not None
        p, n = stream.n_views, mean64.numel()
        k_max = self.n_components if isinstance(self.n_components, int) else min(p, n)
        width = min(k_max + self.oversample, p, n)
        gen = torch.Generator(device="cpu").manual_seed(self.seed)
        omega = torch.randn(p, width, generator=gen, dtype=torch.float64).to(mean64.device)
        q, z, total = randomized_passes(stream, mean64, omega, self.n_iter, lambda t: t, row_offset=0)
        stream.check_result(z, "the sketch Xc Q")
        self.n_passes_ = 3 + self.n_iter
        return self._from_sketch(stream, mean64, q, z, total)

    def _from_sketch(
        self, stream: _Stream, mean64: torch.Tensor, q: torch.Tensor, z: torch.Tensor, total: torch.Tensor
    ) -> _Fit:
        """Components from Z = Xc Q (P, l) with Q (N, l) orthonormal: Z = U S Wᵀ, Xc ≈ U S (Q W)ᵀ."""
        assert stream.n_views is not None and stream.dtype is not None
        _, s, wt = torch.linalg.svd(z, full_matrices=False)
        eigvals = s.square()
        kept = above_tolerance(eigvals, total, mean64, stream.n_views, stream.dtype)
        k = select_k(self.n_components, kept, total, "the streamed views", stream.n_views)
        if not isinstance(self.n_components, int) and float(eigvals[:k].sum() / total) < self.n_components:
            raise ValueError(
                f"n_components={self.n_components} (energy fraction) needs more than the {eigvals.numel()} "
                "directions of the randomized sketch: raise oversample or use method='exact'"
            )
        return self._finish(stream, mean64, wt[:k] @ q.T, eigvals[:k], total)


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


def _mean(stream: _Stream) -> torch.Tensor:
    """Pass 1: the (N,) mean view, summed in float64, and the blocks' finiteness.

    A block's float64 column sums are finite exactly when its values are (float32 views
    cannot overflow them), so the sums, (N,) per block, are checked instead of every value.
    """
    total: torch.Tensor | None = None
    count = 0
    for b in stream:
        part = torch.sum(b, dim=0, dtype=torch.float64)
        if not bool(torch.isfinite(part).all()):
            what = f"{stream.name}[{stream.index}]"
            check_finite(b, what)  # names the NaN or infinite values
            raise ValueError(f"{what} is too large: its float64 column sums overflow (rescale the views)")
        total = part if total is None else total + part
        count += b.shape[0]
    if total is None:
        raise ValueError("blocks must hold at least 2 views in all, got P=0")
    return total / count


def randomized_passes(
    stream: Iterable[torch.Tensor],
    mean64: torch.Tensor,
    omega: torch.Tensor,
    n_iter: int,
    all_reduce: Callable[[torch.Tensor], torch.Tensor],
    row_offset: int,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The range finder's passes over (this process's) blocks.

    Args:
        stream: the blocks, (P_b, N) each; iterated 2 + ``n_iter`` times.
        mean64: (N,) float64 mean of all views (of all processes).
        omega: (P, l) float64 test matrix, rows indexed by the global view number.
        n_iter: power iterations.
        all_reduce: sums a tensor over processes (identity in one process).
        row_offset: global number of this process's first view.

    Returns:
        Q (N, l) orthonormal, Z = Xc Q (P, l) (all processes' rows, summed in), and
        trace(Xc Xcᵀ), all float64.
    """
    mean = None
    y = torch.zeros(mean64.numel(), omega.shape[1], dtype=torch.float64, device=mean64.device)
    start = row_offset
    for b in stream:
        mean = mean64.to(b.dtype) if mean is None else mean
        stop = start + b.shape[0]
        y += ((b - mean).T @ omega[start:stop].to(b.dtype)).double()
        start = stop
    y = all_reduce(y)
    for _ in range(n_iter):
        q = torch.linalg.qr(y).Q
        y = torch.zeros_like(y)
        for b in stream:
            bc = b - mean64.to(b.dtype)
            qb = q.to(b.dtype)
            y += (bc.T @ (bc @ qb)).double()
        y = all_reduce(y)
    q = torch.linalg.qr(y).Q
    z = torch.zeros(omega.shape, dtype=torch.float64, device=mean64.device)
    total = torch.zeros((), dtype=torch.float64, device=mean64.device)
    start = row_offset
    for b in stream:
        bc = b - mean64.to(b.dtype)
        stop = start + b.shape[0]
        z[start:stop] = (bc @ q.to(b.dtype)).double()
        total += bc.double().square().sum()
        start = stop
    return q, all_reduce(z), all_reduce(total)
