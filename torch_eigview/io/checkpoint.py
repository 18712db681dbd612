"""Versioned save and load of a fitted recognizer (eigenspace + gallery) in one file.

The file is a ``torch.save`` of plain tensors, numbers and strings only, so it loads with
``torch.load(weights_only=True)``: loading never runs code from the file.
"""

from __future__ import annotations

import json
import os
from typing import Any

import torch

from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = ["FORMAT", "FORMAT_VERSION", "load_recognizer", "save_recognizer"]

FORMAT = "torch_eigview.recognizer"
FORMAT_VERSION = 1


def save_recognizer(
    path: str | os.PathLike[str],
    recognizer: NearestNeighborRecognizer,
    metadata: dict[str, Any] | None = None,
) -> None:
    """Writes the recognizer (projection, gallery, labels, poses) and JSON-like ``metadata``."""
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
        "metadata": meta,
    }
    torch.save(payload, os.fspath(path))


def load_recognizer(path: str | os.PathLike[str]) -> tuple[NearestNeighborRecognizer, dict[str, Any]]:
    """Reads a file written by :func:`save_recognizer`.

    Returns:
        ``(recognizer, metadata)``.

    Raises:
        ValueError: the file is missing, truncated, not one of ours, or of another version.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ValueError(f"model file {path!r} does not exist")
    if not os.path.isfile(path):
        raise ValueError(f"model file {path!r} is not a file")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # a truncated zip or an arbitrary file: report which
        raise ValueError(f"model file {path!r} could not be read as a torch_eigview model: {exc}") from exc
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(
            f"model file {path!r} is not a torch_eigview recognizer (format {FORMAT!r} expected)"
        )
    if payload.get("version") != FORMAT_VERSION:
        raise ValueError(
            f"model file {path!r} has format version {payload.get('version')!r}; "
            f"this torch_eigview reads version {FORMAT_VERSION}"
        )
    try:
        shape = payload["image_shape"]
        projection = EigenProjection(
            payload["mean"],
            payload["components"],
            payload["eigenvalues"] if payload["eigenvalues"].numel() else None,
            tuple(shape) if shape is not None else None,
            unit_norm=bool(payload["unit_norm"]),
        )
        recognizer = NearestNeighborRecognizer(
            projection, payload["codes"], payload["labels"], payload["poses"], payload["label_names"]
        )
        return recognizer, dict(payload["metadata"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(
            f"model file {path!r} is a damaged or incomplete torch_eigview model: {exc!r}"
        ) from exc
