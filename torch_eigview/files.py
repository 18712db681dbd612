"""Writing files so that nothing is lost: output paths checked up front, atomic replacement.

Every file the package writes (checkpoints, ONNX graphs, JSON records, figures) goes
through :func:`atomic_output` or :func:`atomic_open`: the bytes go to a temporary file in
the destination's folder, are flushed and fsynced, and only then replace the destination
with ``os.replace``. A run that fails or is killed part-way therefore leaves the previous
file as it was. Scratch files that live as long as an object (the view cache) come from
:func:`scratch_file`.

Every temporary file carries :data:`TEMP_MARK` in its name and an exclusive ``flock`` for as
long as its writer lives. The kernel drops the lock when the writer dies, even by SIGKILL,
so :func:`remove_stale` (run before each new temporary file is made) can tell the files of
dead writers from those being written, and deletes only the former. Nothing in the package
reads a file with the mark, so a leftover is never mistaken for an output.

:func:`check_output_path` validates a destination before any computation starts, so a long
run never ends with a traceback instead of its results.

Torch-free on purpose: ``eigview predict`` writes its JSON with it.

Example:
    >>> import json, os, tempfile
    >>> folder = tempfile.mkdtemp()
    >>> path = check_output_path(os.path.join(folder, "r.json"), "--json")
    >>> with atomic_open(path, "w") as fh:
    ...     json.dump({"accuracy": 98.2}, fh)
    >>> with open(path) as fh:
    ...     json.load(fh), os.listdir(folder)
    ({'accuracy': 98.2}, ['r.json'])
"""

from __future__ import annotations

import contextlib
import errno
import functools
import json
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from typing import IO, Any

try:  # POSIX; elsewhere temporary files are not locked and never cleaned as stale
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "TEMP_MARK",
    "atomic_open",
    "atomic_output",
    "check_output_path",
    "check_outputs",
    "remove_stale",
    "scratch_file",
    "write_error",
    "write_json",
]

TEMP_MARK = ".eigview-tmp-"
_NAME_KEEP = 80  # characters of the destination's name kept in a temporary name (NAME_MAX is 255)

# Errors of the write itself, reported with the destination's name; others pass unchanged.
_WRITE_ERRNOS = {errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EIO, errno.EROFS}

PathLike = str | os.PathLike[str]


def _special_kind(mode: int) -> str:
    for test, kind in (
        (stat.S_ISCHR, "character device"),
        (stat.S_ISBLK, "block device"),
        (stat.S_ISFIFO, "FIFO"),
        (stat.S_ISSOCK, "socket"),
    ):
        if test(mode):
            return kind
    return "special file"


def check_output_path(path: object, name: str, *, inputs: Iterable[tuple[str, object]] = ()) -> str:
    """Checks that ``path`` can be written as a regular file, before any work starts.

    Args:
        path: the file to write (str or path-like); a symbolic link is followed.
        name: the argument or flag that gave it, for messages (``"--json"``, ``"path"``).
        inputs: ``(argument name, path)`` of the files the same run reads; ``path`` may be
            none of them.

    Returns:
        ``path`` as a string, unchanged.

    Raises:
        TypeError: ``path`` is not a str or path-like.
        ValueError: ``path`` is empty, a directory or a special file (device, FIFO,
            socket), its folder is missing or not writable, or it is one of ``inputs``.
    """
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name} must be a file path (str or os.PathLike), got {type(path).__name__}")
    text = os.fspath(path)
    if not text:
        raise ValueError(f"{name} must be a file path, got an empty string")
    target = os.path.realpath(text)
    if os.path.isdir(target):
        raise ValueError(f"{name}={text!r} is a directory; give the path of a file to write")
    if os.path.exists(target) and not os.path.isfile(target):
        kind = _special_kind(os.stat(target).st_mode)
        raise ValueError(f"{name}={text!r} is a {kind}, not a regular file; give the path of a file to write")
    folder = os.path.dirname(target)
    if not os.path.isdir(folder):
        raise ValueError(f"{name}={text!r}: the folder {os.path.dirname(text) or '.'!r} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{name}={text!r}: the folder {folder!r} is not writable")
    if not os.path.exists(target):  # a new file cannot be one of the (existing) inputs
        return text
    for input_name, other in inputs:
        if isinstance(other, (str, os.PathLike)) and os.fspath(other) and _same_file(target, other):
            raise ValueError(
                f"{name}={text!r} is the same file as {input_name}={os.fspath(other)!r}: writing it "
                "would destroy the input; give another output path"
            )
    return text


def check_outputs(outputs: Iterable[tuple[str, object]], inputs: Iterable[tuple[str, object]] = ()) -> None:
    """:func:`check_output_path` for each ``(flag, path)`` of a run whose path is not None
    or empty, and no two of them the same file.

    Raises:
        ValueError: as :func:`check_output_path`, or two outputs name the same file.
    """
    given = [(name, path) for name, path in outputs if path is not None and path != ""]
    inputs = list(inputs)
    seen: dict[str, str] = {}
    for name, path in given:
        text = check_output_path(path, name, inputs=inputs)
        target = os.path.realpath(text)
        if target in seen:
            raise ValueError(f"{name}={text!r} and {seen[target]} name the same file; give each its own path")
        seen[target] = f"{name}={text!r}"


def _same_file(target: str, other: str | os.PathLike[str]) -> bool:
    try:
        return os.path.samefile(target, other)
    except OSError:  # the input is missing: its own check reports that
        return False


@functools.cache
def _file_mode() -> int:
    """0o666 less the umask: the mode ``open()`` would give a new file (mkstemp gives 0o600)."""
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


def remove_stale(folder: PathLike) -> list[str]:
    """Deletes the temporary files in ``folder`` whose writer has died; returns their paths.

    A file counts as stale when its name carries :data:`TEMP_MARK` and nobody holds its
    lock, i.e. the process that made it ended (SIGKILL included) before renaming or
    deleting it. Files being written are locked and left alone.
    """
    if fcntl is None:  # pragma: no cover - Windows
        return []
    removed: list[str] = []
    with contextlib.suppress(OSError), os.scandir(folder) as entries:
        candidates = [e.path for e in entries if TEMP_MARK in e.name and e.is_file(follow_symlinks=False)]
    for path in candidates:
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if os.path.samestat(os.fstat(fd), os.stat(path, follow_symlinks=False)):
                os.unlink(path)
                removed.append(path)
        except OSError:  # locked by a live writer, or gone meanwhile
            pass
        finally:
            os.close(fd)
    return removed


def scratch_file(folder: PathLike, prefix: str, suffix: str = "") -> tuple[int, str]:
    """A new, locked temporary file in ``folder``: ``(fd, path)``; stale ones are removed first.

    The name is ``prefix + TEMP_MARK + random + suffix``. The lock lasts while ``fd`` (or
    a duplicate of it) is open; close it only after the file is renamed or deleted.
    """
    folder = os.fspath(folder)
    remove_stale(folder)
    while True:
        fd, path = tempfile.mkstemp(prefix=prefix + TEMP_MARK, suffix=suffix, dir=folder)
        if fcntl is None:  # pragma: no cover - Windows
            return fd, path
        # Blocking: a cleaner holds the lock of a file it judges stale only for a moment.
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            if os.path.samestat(os.fstat(fd), os.stat(path)):
                return fd, path
        except FileNotFoundError:
            pass
        os.close(fd)  # a cleaner took it between mkstemp and the lock: make another


def _fsync_folder(folder: str) -> None:
    """Makes the rename itself durable (where the platform allows opening a folder)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def write_error(path: PathLike, cause: BaseException) -> OSError:
    """The error of a failed write of ``path``: "could not write 'PATH' (REASON); any previous
    file is unchanged", with the errno of the first ``OSError`` in ``cause``'s chain (a
    writer such as ``torch.save`` reports a failed ``write`` as its own ``RuntimeError``,
    the ``OSError`` as its context)."""
    seen: set[int] = set()
    link: BaseException | None = cause
    while link is not None and id(link) not in seen:
        if isinstance(link, OSError):
            return OSError(
                link.errno,
                f"could not write {os.fspath(path)!r} ({link.strerror or link}); any previous file is unchanged",
            )
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return OSError(f"could not write {os.fspath(path)!r} ({cause}); any previous file is unchanged")


@contextlib.contextmanager
def atomic_output(path: PathLike) -> Iterator[str]:
    """Yields a temporary path to write; on success it replaces ``path`` atomically.

    For writers that take a file name (``torch.save``, ``ONNXProgram.save``). The
    temporary file is in ``path``'s folder (so ``os.replace`` is a rename, never a copy),
    fsynced before the rename, and deleted on any exception, the previous ``path`` left as
    it was.

    Raises:
        OSError: the write failed (disk full, file-size limit, …); the message names
            ``path`` and says that the previous file is unchanged.
    """
    text = os.fspath(path)
    target = os.path.realpath(text)
    folder, base = os.path.split(target)
    fd, tmp = scratch_file(folder, "." + base[:_NAME_KEEP])
    try:
        os.fchmod(fd, _file_mode())
        yield tmp
        with open(tmp, "rb+") as fh:  # the writer may have reopened the file by name
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno in _WRITE_ERRNOS:
            raise write_error(text, exc) from exc
        raise
    finally:
        os.close(fd)
    _fsync_folder(folder)


@contextlib.contextmanager
def atomic_open(path: PathLike, mode: str = "w") -> Iterator[IO[Any]]:
    """An open file (``"w"`` text or ``"wb"`` binary) that replaces ``path`` only when closed
    without an exception. See :func:`atomic_output`."""
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    with atomic_output(path) as tmp, open(tmp, mode, encoding=None if "b" in mode else "utf-8") as fh:
        yield fh
        fh.flush()


def write_json(path: PathLike, record: object, **dump_kwargs: Any) -> None:
    """Writes ``record`` as indented JSON, atomically (see :func:`atomic_output`)."""
    with atomic_open(path, "w") as fh:
        json.dump(record, fh, indent=2, **dump_kwargs)
        fh.write("\n")
