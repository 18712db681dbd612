"""Versioned, checksummed save and load of a fitted recognizer, or of a module's state_dict.

A file is a ``torch.save`` of plain tensors, numbers and strings only, so it loads with
``torch.load(weights_only=True)``: loading never runs code from the file. It records the
SHA-256 of its tensors (dtype, shape and bytes) and of every other entry, metadata included,
and loading recomputes it: a bit flipped anywhere, on disk or in transit, is refused with
an error naming the file, never loaded as a model that answers wrongly. Files are written
atomically (:func:`torch_eigview.files.atomic_output`): a failed or killed save leaves the
previous file as it was.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from typing import Any

import torch

from torch_eigview.files import atomic_output, check_output_path
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "STATE_DICT_FORMAT",
    "load_recognizer",
    "load_state_dict",
    "payload_digest",
    "save_recognizer",
    "save_state_dict",
]

FORMAT = "torch_eigview.recognizer"
# Version 2 added the checksum; version 1 files (no checksum) are refused, see _read.
FORMAT_VERSION = 2
STATE_DICT_FORMAT = "torch_eigview.state_dict"
STATE_DICT_VERSION = 1
_DIGEST_KEY = "sha256"


def _feed(h: Any, value: object) -> None:
    """Feeds ``value`` to the hash in an unambiguous encoding: every item says its kind and size."""
    if isinstance(value, torch.Tensor):
        t = value.detach().cpu().contiguous().reshape(-1)
        h.update(f"tensor {t.dtype} {list(value.shape)};".encode())
        h.update(t.view(torch.uint8).numpy())  # the raw bytes, no copy
    elif isinstance(value, Mapping):
        h.update(f"dict {len(value)};".encode())
        for key in sorted(value, key=str):
            _feed(h, str(key))
            _feed(h, value[key])
    elif isinstance(value, (list, tuple)):
        h.update(f"list {len(value)};".encode())
        for item in value:
            _feed(h, item)
    else:  # str, int, float, bool, None: JSON spells each exactly and distinctly
        h.update(f"value {json.dumps(value)};".encode())


def payload_digest(payload: Mapping[str, object]) -> str:
    """SHA-256 (hex) of a file's entries, all but the digest itself.

    Example:
        >>> payload_digest({"a": torch.zeros(2)}) == payload_digest({"a": torch.zeros(2)})
        True
        >>> payload_digest({"a": torch.zeros(2)}) == payload_digest({"a": torch.zeros(2, 1)})
        False
    """
    h = hashlib.sha256()
    _feed(h, {k: v for k, v in payload.items() if k != _DIGEST_KEY})
    return h.hexdigest()


def _write(path: str | os.PathLike[str], payload: dict[str, Any]) -> None:
    """Checks ``path``, adds the digest and writes ``payload`` atomically."""
    text = check_output_path(path, "path")
    payload[_DIGEST_KEY] = payload_digest(payload)
    with atomic_output(text) as tmp, open(tmp, "wb") as fh:
        # A Python file: a failed write raises OSError with its errno (disk full, file-size
        # limit), where torch's own file writer reports only "iostream error".
        torch.save(payload, fh)


def _read(path: str | os.PathLike[str], fmt: str, version: int, what: str) -> dict[str, Any]:
    """Loads (weights only) and verifies a file of format ``fmt``; ``what`` names it in errors."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ValueError(f"model file {path!r} does not exist")
    if not os.path.isfile(path):
        raise ValueError(f"model file {path!r} is not a file")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # a truncated or damaged zip, or an arbitrary file: report which
        raise ValueError(
            f"model file {path!r} could not be read as a torch_eigview model (damaged, truncated or "
            f"another kind of file): {exc}"
        ) from exc
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        raise ValueError(f"model file {path!r} is not a torch_eigview {what} (format {fmt!r} expected)")
    if payload.get("version") != version:
        older = " (version 1 had no checksum: save the model again)" if payload.get("version") == 1 else ""
        raise ValueError(
            f"model file {path!r} has format version {payload.get('version')!r}; this torch_eigview "
            f"reads version {version}{older}"
        )
    recorded = payload.get(_DIGEST_KEY)
    try:
        actual = payload_digest(payload)
    except (TypeError, ValueError, RuntimeError) as exc:  # e.g. a key flipped into a non-string
        raise ValueError(f"{path}: checksum mismatch: the file is corrupted ({exc})") from exc
    if recorded != actual:
        said = f"{recorded[:16]}…" if isinstance(recorded, str) else "no checksum"
        raise ValueError(
            f"{path}: checksum mismatch: the file is corrupted (the SHA-256 of its contents is "
            f"{actual[:16]}…, torch_eigview recorded {said}); restore it from a copy or write it again"
        )
    return payload


def save_recognizer(
    path: str | os.PathLike[str],
    recognizer: NearestNeighborRecognizer,
    metadata: dict[str, Any] | None = None,
) -> None:
    """Writes the recognizer (projection, gallery, labels, poses) and JSON-like ``metadata``.

    The file replaces ``path`` atomically, with the SHA-256 of its contents.

    Raises:
        TypeError: ``recognizer`` is not a recognizer over an :class:`EigenProjection`, or
            ``metadata`` holds non-JSON values.
        ValueError: ``path`` cannot be written (a directory, a special file, a missing or
            read-only folder).
        OSError: the write failed (disk full, file-size limit); ``path`` is unchanged.
    """
    check_output_path(path, "path")
    if not isinstance(recognizer, NearestNeighborRecognizer):
        raise TypeError(f"recognizer must be a NearestNeighborRecognizer, got {type(recognizer).__name__}")
    meta = dict(metadata or {})
    try:
        json.dumps(meta, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"metadata must hold JSON values only (str, int, float, bool, None, lists, dicts): {exc}"
        ) from exc
    proj = recognizer.projection
    if not isinstance(proj, EigenProjection):
        raise TypeError(
            f"recognizer.projection must be an EigenProjection (format version {FORMAT_VERSION} holds a "
            f"linear eigenspace), got {type(proj).__name__}"
        )
    payload = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "mean": proj.mean.detach().cpu(),
        "components": proj.components.detach().cpu(),
        "eigenvalues": proj.eigenvalues.detach().cpu(),
        "image_shape": list(proj.image_shape) if proj.image_shape is not None else None,
        "unit_norm": proj.unit_norm,
        "codes": recognizer.codes.detach().cpu(),
        "labels": recognizer.labels.detach().cpu(),
        "poses": recognizer.poses.detach().cpu(),
        "label_names": recognizer.label_names,
        "reject_thresholds": recognizer.reject_thresholds.detach().cpu(),
        "metadata": meta,
    }
    _write(path, payload)


def load_recognizer(path: str | os.PathLike[str]) -> tuple[NearestNeighborRecognizer, dict[str, Any]]:
    """Reads a file written by :func:`save_recognizer`, after verifying its checksum.

    Returns:
        ``(recognizer, metadata)``.

    Raises:
        ValueError: the file is missing, truncated, corrupted (checksum mismatch), not one
            of ours, or of another version.
    """
    payload = _read(path, FORMAT, FORMAT_VERSION, "recognizer")
    try:
        shape = payload["image_shape"]
        projection = EigenProjection(
            payload["mean"],
            payload["components"],
            payload["eigenvalues"] if payload["eigenvalues"].numel() else None,
            tuple(shape) if shape is not None else None,
            unit_norm=bool(payload["unit_norm"]),
        )
        # Files written before rejection existed have no thresholds: (0,) means none too.
        thresholds = payload.get("reject_thresholds")
        recognizer = NearestNeighborRecognizer(
            projection,
            payload["codes"],
            payload["labels"],
            payload["poses"],
            payload["label_names"],
            thresholds if thresholds is not None and thresholds.numel() else None,
        )
        return recognizer, dict(payload["metadata"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(
            f"model file {os.fspath(path)!r} is a damaged or incomplete torch_eigview model: {exc!r}"
        ) from exc


def save_state_dict(path: str | os.PathLike[str], state_dict: Mapping[str, object]) -> None:
    """Writes a module's ``state_dict`` atomically, with its SHA-256.

    Values are tensors, or the plain values of a module's extra state (``image_shape``,
    ``unit_norm``).

    Read it back with :func:`load_state_dict`, then ``module.load_state_dict(...)``.

    Raises:
        TypeError: ``state_dict`` is not a mapping of str to tensors or plain values.
        ValueError: ``path`` cannot be written.
        OSError: the write failed; ``path`` is unchanged.
    """
    check_output_path(path, "path")
    if not isinstance(state_dict, Mapping):
        raise TypeError(f"state_dict must be a mapping of str to tensors, got {type(state_dict).__name__}")
    entries: dict[str, Any] = {}
    for key, value in state_dict.items():
        if not isinstance(key, str):
            raise TypeError(f"state_dict keys must be str, got {key!r}")
        if isinstance(value, torch.Tensor):
            entries[key] = value.detach().cpu()
            continue
        try:  # a module's extra state: plain values that weights_only loading accepts
            json.dumps(value, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"state_dict[{key!r}] must be a tensor or JSON-like values: {exc}") from exc
        entries[key] = value
    _write(path, {"format": STATE_DICT_FORMAT, "version": STATE_DICT_VERSION, "state_dict": entries})


def load_state_dict(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Reads a file written by :func:`save_state_dict`, after verifying its checksum.

    Raises:
        ValueError: the file is missing, truncated, corrupted, or not a state_dict file.
    """
    payload = _read(path, STATE_DICT_FORMAT, STATE_DICT_VERSION, "state_dict")
    state = payload.get("state_dict")
    if not isinstance(state, dict):
        raise ValueError(f"model file {os.fspath(path)!r} is a damaged torch_eigview state_dict file")
    return state
