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

import contextlib
import os
import tempfile
import weakref
from collections.abc import Iterator
from types import TracebackType

import numpy as np
import torch

from torch_eigview.check import check_finite, check_float_tensor, check_int
from torch_eigview.files import scratch_file

__all__ = ["ViewCache"]

_DTYPES = {torch.float32: np.float32, torch.float16: np.float16, torch.float64: np.float64}


def _discard(fd: int, path: str) -> None:
    """Deletes the file, then closes it: the lock is held until the name is gone."""
    with contextlib.suppress(OSError):
        os.unlink(path)
    with contextlib.suppress(OSError):
        os.close(fd)


def _check_directory(directory: object) -> str:
    if directory is None:
        return tempfile.gettempdir()
    if isinstance(directory, bytes) or not isinstance(directory, (str, os.PathLike)):
        raise TypeError(
            f"directory must be a folder path (str or os.PathLike), got {type(directory).__name__}"
        )
    text = os.fspath(directory)
    if not os.path.isdir(text):
        what = "is not a folder" if os.path.exists(text) else "does not exist"
        raise ValueError(f"directory={text!r} {what}; the view cache needs an existing, writable folder")
    if not os.access(text, os.W_OK | os.X_OK):
        raise ValueError(f"directory={text!r} is not writable; the view cache needs a writable folder")
    return text


def _pwrite_all(fd: int, data: memoryview, offset: int) -> None:
    done = 0
    while done < len(data):
        done += os.pwrite(fd, data[done:], offset + done)


def _pread_all(fd: int, buf: memoryview, offset: int) -> bool:
    """Fills ``buf`` from ``offset`` (one pread returns at most ~2 GiB); False at an early end."""
    done = 0
    while done < len(buf):
        n = os.preadv(fd, [buf[done:]], offset + done)
        if n == 0:
            return False
        done += n
    return True


class ViewCache:
    """An append-only on-disk store of view blocks; calling it iterates the blocks again.

    Args:
        directory: an existing folder for the file (default: the system's temp folder).
        dtype: storage dtype, ``torch.float32`` (exact for float32 views, the default),
            ``torch.float16`` (half the disk and read traffic; views are rounded to 11
            significant bits) or ``torch.float64``.
        max_bytes: the most bytes the file may grow to (default: no limit but the free
            space of ``directory``).

    Blocks come back as float32 (float64 when stored so) tensors of the shape they were
    appended with. Use it as a context manager, or call :meth:`close`, to delete the file.

    An append that fails part-way (disk full, file-size limit) is rolled back: the file is
    truncated to the blocks before it, which read back as they were, and the error says
    so; if even the truncation fails the cache is marked broken and every later call
    raises. The file is named with :data:`torch_eigview.files.TEMP_MARK` and locked while
    the cache lives, so the file of a process killed mid-write is removed by the next
    cache made in the same folder.

    Example:
        >>> with ViewCache() as cache:
        ...     cache.append(torch.rand(41, 1, 8, 8))
        ...     cache.append(torch.rand(41, 1, 8, 8))
        ...     [b.shape[0] for b in cache()]
        [41, 41]
    """

    def __init__(
        self,
        directory: str | os.PathLike[str] | None = None,
        dtype: torch.dtype = torch.float32,
        max_bytes: int | None = None,
    ) -> None:
        if dtype not in _DTYPES:
            raise ValueError(f"dtype must be one of {list(_DTYPES)}, got {dtype}")
        self.max_bytes = None if max_bytes is None else check_int(max_bytes, "max_bytes", minimum=1)
        self.dtype = dtype
        self._fd, self.path = scratch_file(_check_directory(directory), "eigview-views", ".bin")
        self._blocks: list[tuple[int, tuple[int, ...]]] = []  # (byte offset, shape)
        self._end = 0
        self._closed = False
        self._broken: str | None = None
        # The file goes with the object even when close() is never called.
        self._finalizer = weakref.finalize(self, _discard, self._fd, self.path)

    @property
    def n_views(self) -> int:
        """P, the views stored so far."""
        return sum(shape[0] for _, shape in self._blocks)

    def _check_usable(self, action: str) -> None:
        if self._closed:
            raise ValueError(f"views cannot be {action} a closed ViewCache (its file is deleted)")
        if self._broken is not None:
            raise ValueError(f"ViewCache {self.path} is broken, views cannot be {action} it: {self._broken}")

    def _check_space(self, nbytes: int) -> None:
        if self.max_bytes is not None and self._end + nbytes > self.max_bytes:
            raise ValueError(
                f"the block of {nbytes} bytes would grow ViewCache {self.path} to {self._end + nbytes} "
                f"bytes, above max_bytes={self.max_bytes}; raise max_bytes or store float16 views"
            )
        st = os.fstatvfs(self._fd)
        free = st.f_bavail * st.f_frsize
        if nbytes > free:
            raise ValueError(
                f"the block of {nbytes} bytes does not fit in the {free} bytes free in the folder of "
                f"ViewCache {self.path}; give ViewCache(directory=...) a folder with more space"
            )

    def append(self, views: torch.Tensor) -> None:
        """Stores a block of views (P_i, ...) after the previous ones.

        Raises:
            TypeError: ``views`` is not a float tensor.
            ValueError: non-finite values, no views, a view shape different from the first
                block's, no room for the block, or a closed or broken cache.
            OSError: the write failed part-way; the cache was rolled back to the earlier
                blocks (the message says so).
        """
        self._check_usable("appended to")
        v = check_float_tensor(views, "views")
        if v.ndim < 2 or v.shape[0] == 0:
            raise ValueError(f"views must have shape (P_i, ...) with P_i >= 1, got {tuple(v.shape)}")
        if self._blocks and tuple(v.shape[1:]) != self._blocks[0][1][1:]:
            raise ValueError(
                f"views must have the view shape of the first block {self._blocks[0][1][1:]}, got {tuple(v.shape[1:])}"
            )
        stored = v.detach().to("cpu", self.dtype).contiguous()
        check_finite(stored, f"views (as {self.dtype})")  # after the cast: float16 overflows above 65504
        data = stored.numpy().reshape(-1)
        self._check_space(data.nbytes)
        try:
            _pwrite_all(self._fd, data.data.cast("B"), self._end)  # the tensor's buffer, no copy
        except BaseException as exc:
            self._roll_back(exc)
            if isinstance(exc, OSError):
                raise OSError(
                    exc.errno,
                    f"appending {data.nbytes} bytes to ViewCache {self.path} failed ({exc.strerror}); "
                    f"the cache was rolled back to its {len(self._blocks)} earlier block(s)",
                ) from exc
            raise
        self._blocks.append((self._end, tuple(v.shape)))
        self._end += data.nbytes

    def _roll_back(self, exc: BaseException) -> None:
        """Cuts the bytes of a failed append; marks the cache broken when even that fails."""
        try:
            os.ftruncate(self._fd, self._end)
        except OSError as cut:
            self._broken = f"an append failed ({exc!r}) and its partial bytes could not be removed ({cut!r})"

    def __call__(self) -> Iterator[torch.Tensor]:
        """The stored blocks, in order, read from disk one at a time.

        Raises:
            ValueError: the cache is closed or broken, or its file was changed by someone else.
        """
        self._check_usable("read from")
        size = os.fstat(self._fd).st_size
        if size != self._end:
            raise ValueError(
                f"ViewCache {self.path} holds {size} bytes but {self._end} were appended: the file was "
                "changed outside the cache, its views cannot be trusted"
            )
        out_dtype = torch.float64 if self.dtype == torch.float64 else torch.float32
        for offset, shape in self._blocks:
            data = np.empty(int(np.prod(shape)), dtype=_DTYPES[self.dtype])
            if not _pread_all(self._fd, data.data.cast("B"), offset):
                raise ValueError(f"ViewCache {self.path} ended before its block at byte {offset}")
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
