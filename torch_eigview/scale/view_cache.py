"""Synthesized views kept once on disk and re-read block by block (bounded memory).

The exact streaming eigenspace (:class:`~torch_eigview.decomposition.streaming.StreamingEigenspace`,
Gram by panels) and the randomized range finder pass over the views several times. When
the views are synthesized (flow + warp, the expensive part), re-synthesizing them on
every pass multiplies the cost; holding them all in memory is what bounded memory rules
out. A :class:`ViewCache` stores each object's block as it is synthesized in one flat
file and is itself a re-generable block source: every call reads the blocks back, one
at a time, with plain file reads (no memory map, so the resident set holds one block).
"""

from __future__ import annotations

import os
import tempfile
import weakref
from collections.abc import Iterator
from types import TracebackType

import numpy as np
import torch

from torch_eigview.check import check_finite, check_float_tensor

__all__ = ["ViewCache"]

_DTYPES = {torch.float32: np.float32, torch.float16: np.float16, torch.float64: np.float64}


def _remove(path: str) -> None:
    if os.path.exists(path):
        os.remove(path)


class ViewCache:
    """An append-only on-disk store of view blocks; calling it iterates the blocks again.

    Args:
        directory: where the temporary file goes (default: the system's temp directory).
        dtype: storage dtype, ``torch.float32`` (exact for float32 views, the default),
            ``torch.float16`` (half the disk and read traffic; views are rounded to 11
            significant bits) or ``torch.float64``.

    Blocks come back as float32 (float64 when stored so) tensors of the shape they were
    appended with. Use it as a context manager, or call :meth:`close`, to delete the file.

    Example:
        >>> with ViewCache() as cache:
        ...     cache.append(torch.rand(41, 1, 8, 8))
        ...     cache.append(torch.rand(41, 1, 8, 8))
        ...     [b.shape[0] for b in cache()]
        [41, 41]
    """

    def __init__(self, directory: str | None = None, dtype: torch.dtype = torch.float32) -> None:
        if dtype not in _DTYPES:
            raise ValueError(f"dtype must be one of {list(_DTYPES)}, got {dtype}")
        self.dtype = dtype
        fd, self.path = tempfile.mkstemp(prefix="eigview-views-", suffix=".bin", dir=directory)
        os.close(fd)
        self._blocks: list[tuple[int, tuple[int, ...]]] = []  # (byte offset, shape)
        self._end = 0
        self._closed = False
        # The file goes with the object even when close() is never called.
        self._finalizer = weakref.finalize(self, _remove, self.path)

    @property
    def n_views(self) -> int:
        """P, the views stored so far."""
        return sum(shape[0] for _, shape in self._blocks)

    def append(self, views: torch.Tensor) -> None:
        """Stores a block of views (P_i, ...) after the previous ones.

        Raises:
            TypeError: ``views`` is not a float tensor.
            ValueError: non-finite values, no views, or a view shape different from the
                first block's.
        """
        if self._closed:
            raise ValueError("views cannot be appended to a closed ViewCache (its file is deleted)")
        v = check_float_tensor(views, "views")
        if v.ndim < 2 or v.shape[0] == 0:
            raise ValueError(f"views must have shape (P_i, ...) with P_i >= 1, got {tuple(v.shape)}")
        if self._blocks and tuple(v.shape[1:]) != self._blocks[0][1][1:]:
            raise ValueError(
                f"views must have the view shape of the first block {self._blocks[0][1][1:]}, got {tuple(v.shape[1:])}"
            )
        stored = v.detach().to("cpu", self.dtype).contiguous()
        check_finite(stored, f"views (as {self.dtype})")  # after the cast: float16 overflows above 65504
        data = stored.numpy()
        with open(self.path, "ab") as fh:
            fh.write(data.reshape(-1).data)  # the tensor's own buffer, no copy
        self._blocks.append((self._end, tuple(v.shape)))
        self._end += data.nbytes

    def __call__(self) -> Iterator[torch.Tensor]:
        """The stored blocks, in order, read from disk one at a time."""
        out_dtype = torch.float64 if self.dtype == torch.float64 else torch.float32
        with open(self.path, "rb") as fh:
            for offset, shape in self._blocks:
                fh.seek(offset)
                count = int(np.prod(shape))
                data = np.fromfile(fh, dtype=_DTYPES[self.dtype], count=count)
                yield torch.from_numpy(data).reshape(shape).to(out_dtype)

    def close(self) -> None:
        """Deletes the file (idempotent); the cache takes no more views."""
        self._finalizer()
        self._blocks, self._end, self._closed = [], 0, True

    def __enter__(self) -> ViewCache:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"ViewCache(n_views={self.n_views}, dtype={self.dtype}, bytes={self._end})"
