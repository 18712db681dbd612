"""The block source of :class:`~torch_eigview.decomposition.streaming.StreamingEigenspace`:
its validation pass after pass, the check that every pass yields the same views, and the
first pass (the mean)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Sequence

import torch

from torch_eigview.check import check_finite, check_float_tensor, check_int, check_magnitude, check_ndim
from torch_eigview.decomposition._fitted import DTYPES

__all__ = ["BlockSource", "Stream", "blocks_of", "stream_mean"]

BlockSource = Callable[[], Iterable[torch.Tensor]]
"""A callable returning a fresh iterable of (P_b, N) or (P_b, C, H, W) view blocks."""

# A later pass's block digest may differ from the first pass's by rounding only.
_DIGEST_RTOL = 1e-6


def blocks_of(x: torch.Tensor, block_size: int) -> BlockSource:
    """A re-generable source over the rows of an explicit (P, ...) tensor, ``block_size`` rows a block."""
    block_size = check_int(block_size, "block_size", 1)
    return lambda: (x[i : i + block_size] for i in range(0, x.shape[0], block_size))


def _digest(b: torch.Tensor) -> torch.Tensor:
    """(P_b, 2) float64 per view of a (P_b, N) block: its sum, and its values weighted by a
    ramp over the features (which a reordering of the values changes).

    One product with an (N, 2) weight matrix in the block's dtype: no temporary the size of
    the block. (A float64 row sum converts the whole block first; freeing such a block-sized
    temporary on every pass makes glibc raise its mmap threshold, after which the view
    blocks of a ``ViewCache`` fragment the heap and a large build's peak memory grows.)
    Both passes compute the same product on the same data, so their digests agree exactly
    for an unchanged source. The weights are a (2, N) matrix used transposed, so that
    each weight vector lies contiguous in memory, as the block's rows do: a contiguous
    (N, 2) matrix would be read with a stride of 2 along N, the long axis of the product,
    which every block of every pass pays.
    """
    n = b.shape[1]
    ones = torch.ones(n, dtype=b.dtype, device=b.device)
    weights = torch.stack([ones, torch.linspace(1.0, 2.0, n, dtype=b.dtype, device=b.device)])
    return (b @ weights.T).double()


class Stream:
    """Validates the blocks of a source pass after pass: dtype, feature shape and P on every
    pass, and every block's :func:`_digest` against the first pass's, so that a source whose
    values change between passes is an error rather than a silently wrong eigenspace.
    Finiteness is checked by the first pass, :func:`stream_mean`, on each block's column
    sums; the fits also check what they accumulate (:meth:`check_result`)."""

    def __init__(self, source: object, name: str = "blocks") -> None:
        if isinstance(source, torch.Tensor):
            check_ndim(source, name, (2, 4), "(P, N) or (P, C, H, W)")
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
        self.digests: list[torch.Tensor] = []
        self.index = -1  # the source's index of the block last yielded

    def _check_block(self, block: object, what: str) -> torch.Tensor:
        b = check_float_tensor(block, what)
        check_ndim(b, what, (2, 4), "(P_b, N) or (P_b, C, H, W)")
        if b.dtype not in DTYPES:
            raise TypeError(f"{what} must have dtype float32 or float64, got {b.dtype}")
        if self.feature_shape is None:
            if math.prod(b.shape[1:]) == 0:
                raise ValueError(
                    f"{what} must hold at least one value per view (N >= 1), got shape {tuple(b.shape)}"
                )
            self.feature_shape, self.dtype, self.device = tuple(b.shape[1:]), b.dtype, b.device
        elif tuple(b.shape[1:]) != self.feature_shape:
            raise ValueError(
                f"{what} must have shape (P_b, {', '.join(map(str, self.feature_shape))}) like the "
                f"first block, got shape {tuple(b.shape)}"
            )
        elif b.dtype != self.dtype:
            raise TypeError(f"{what} must have the first block's dtype {self.dtype}, got {b.dtype}")
        return b

    def _not_regenerable(self, why: str) -> ValueError:
        return ValueError(
            f"{self.name} is not re-generable: {why} (a source must yield the same views on every call)"
        )

    def _compare(self, j: int, digest: torch.Tensor, what: str) -> None:
        """Block ``j`` of a later pass against the first pass's digest."""
        if j >= len(self.digests) or self.digests[j].shape != digest.shape:
            raise self._not_regenerable(f"a later pass gave {what} where the first pass gave other blocks")
        if not bool(torch.isfinite(digest).all()):
            raise ValueError(
                f"{self.name} gave non-finite values on a later pass ({what}) although the first pass was "
                "finite: the source did not yield the same views on every call (it must)"
            )
        first = self.digests[j]
        scale = float(first.abs().max()) if first.numel() else 0.0
        diff = float((digest - first).abs().max())
        if not diff <= _DIGEST_RTOL * scale:  # NaN fails too
            raise self._not_regenerable(
                f"{what} changed between passes (its per-view sums differ by {diff:.3g}, "
                f"{'relative ' + format(diff / scale, '.3g') if scale else 'from zero'})"
            )

    def __iter__(self) -> Iterator[torch.Tensor]:
        rows: list[int] = []
        first_pass = self.n_views is None
        for i, block in enumerate(self.source()):
            what = f"{self.name}[{i}]"
            b = self._check_block(block, what)
            if b.shape[0] == 0:
                continue
            flat = b.detach().reshape(b.shape[0], -1).to(self.device)
            digest = _digest(flat)
            if first_pass:
                self.digests.append(digest)
            else:
                self._compare(len(rows), digest, what)
            rows.append(b.shape[0])
            self.index = i
            yield flat
        if first_pass:
            self.n_views, self.block_rows = sum(rows), rows
        elif rows != self.block_rows:
            raise self._not_regenerable(
                f"a later pass gave blocks of {rows[:8]}... rows, the first {self.block_rows[:8]}..."
            )

    def check_result(self, x: torch.Tensor, what: str) -> None:
        """Raises ValueError when a sum over later passes is not finite (the first pass was)."""
        if not bool(torch.isfinite(x).all()):
            raise ValueError(
                f"{self.name} gave non-finite values on a later pass ({what} came out non-finite) although the "
                "first pass was finite: the sums overflowed the blocks' dtype (values too large: rescale the views)"
            )

    @property
    def image_shape(self) -> tuple[int, int, int] | None:
        s = self.feature_shape
        return (s[0], s[1], s[2]) if s is not None and len(s) == 3 else None


def stream_mean(stream: Stream) -> torch.Tensor:
    """Pass 1: the (N,) mean view, summed in float64, the blocks' finiteness and magnitude.

    A block's float64 column sums are finite exactly when its values are (float32 views
    cannot overflow them), so the sums, (N,) per block, are checked instead of every value;
    the largest magnitude over all blocks is then checked against the dtype's range
    (:func:`~torch_eigview.check.check_magnitude`), once P is known.
    """
    total: torch.Tensor | None = None
    count = 0
    largest: torch.Tensor | None = None
    for b in stream:
        part = torch.sum(b, dim=0, dtype=torch.float64)
        if not bool(torch.isfinite(part).all()):
            what = f"{stream.name}[{stream.index}]"
            check_finite(b, what)  # names the NaN or infinite values
            raise ValueError(f"{what} is too large: its float64 column sums overflow (rescale the views)")
        lo, hi = torch.aminmax(b)
        peak = torch.maximum(-lo, hi)
        largest = peak if largest is None else torch.maximum(largest, peak)
        total = part if total is None else total + part
        count += b.shape[0]
    if total is None or largest is None:
        raise ValueError("blocks must hold at least 2 views in all, got P=0")
    check_magnitude(largest.reshape(1), stream.name, max(count, total.numel()))
    return total / count
