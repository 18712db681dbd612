"""The SHA-256 of an exported ONNX file, recorded in the file and verified before it is run.

An ONNX file is a serialized ``ModelProto``. Protocol buffers merge concatenated messages,
a repeated field gaining the later items, so appending the bytes of a ``ModelProto`` that
holds only one ``metadata_props`` entry (field 14) adds that entry to the model: onnx and
onnxruntime read the file as before, with one more metadata property,
``torch_eigview.sha256``, whose value is the SHA-256 of every byte before it. The trailer
has a fixed length (:data:`TRAILER_SIZE`), so verifying needs neither onnx nor torch, only
the file: ``eigview predict`` checks a model before onnxruntime sees it, and a bit flipped
in the weights, the graph or the trailer is refused instead of giving wrong answers.
"""

from __future__ import annotations

import hashlib
import os

__all__ = ["DIGEST_KEY", "TRAILER_SIZE", "append_checksum", "verify_checksum"]

DIGEST_KEY = "torch_eigview.sha256"
_HEX_DIGITS = 64
# StringStringEntryProto: field 1 (key) and field 2 (value), both length-delimited strings.
_ENTRY_HEAD = b"\x0a" + bytes([len(DIGEST_KEY)]) + DIGEST_KEY.encode() + b"\x12" + bytes([_HEX_DIGITS])
_ENTRY_SIZE = len(_ENTRY_HEAD) + _HEX_DIGITS
# ModelProto field 14 (metadata_props), wire type 2: tag (14 << 3) | 2, then the entry's length.
_TRAILER_HEAD = bytes([(14 << 3) | 2, _ENTRY_SIZE]) + _ENTRY_HEAD
TRAILER_SIZE = len(_TRAILER_HEAD) + _HEX_DIGITS
_CHUNK = 1 << 20


def _digest(fh: object, size: int) -> str:
    """SHA-256 of the first ``size`` bytes of the open binary file ``fh``, read in chunks."""
    h = hashlib.sha256()
    left = size
    while left:
        chunk = fh.read(min(_CHUNK, left))  # type: ignore[attr-defined]
        if not chunk:
            break
        h.update(chunk)
        left -= len(chunk)
    return h.hexdigest()


def append_checksum(path: str | os.PathLike[str]) -> str:
    """Appends the checksum trailer to a serialized ONNX model; returns the hex digest."""
    with open(path, "rb+") as fh:
        size = fh.seek(0, os.SEEK_END)
        fh.seek(0)
        digest = _digest(fh, size)
        fh.seek(size)
        fh.write(_TRAILER_HEAD + digest.encode("ascii"))
    return digest


def verify_checksum(path: str | os.PathLike[str]) -> None:
    """Checks an exported model against the SHA-256 it records.

    Raises:
        ValueError: the file is missing, not a regular file, has no torch_eigview checksum
            (not exported by ``eigview export`` / :func:`~torch_eigview.io.onnx.export_onnx`,
            or modified since), or its contents do not match the checksum.
    """
    text = os.fspath(path)
    if not os.path.isfile(text):
        what = "does not exist" if not os.path.exists(text) else "is not a regular file"
        raise ValueError(f"ONNX model {text!r} {what}")
    with open(text, "rb") as fh:
        size = fh.seek(0, os.SEEK_END)
        if size < TRAILER_SIZE:
            raise ValueError(f"{text}: checksum missing: the file is truncated or not an exported model")
        fh.seek(size - TRAILER_SIZE)
        trailer = fh.read(TRAILER_SIZE)
        recorded = trailer[len(_TRAILER_HEAD) :]
        if trailer[: len(_TRAILER_HEAD)] != _TRAILER_HEAD:
            raise ValueError(
                f"{text}: checksum missing: the file ends without torch_eigview's {DIGEST_KEY!r} "
                "(corrupted, truncated, modified, or not written by 'eigview export'); export it again"
            )
        fh.seek(0)
        actual = _digest(fh, size - TRAILER_SIZE)
    if recorded != actual.encode("ascii"):
        raise ValueError(
            f"{text}: checksum mismatch: the file is corrupted (the SHA-256 of its contents is "
            f"{actual[:16]}…, the file records {recorded[:16].decode('ascii', 'replace')}…); export it again"
        )
