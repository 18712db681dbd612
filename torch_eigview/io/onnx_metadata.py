"""What an exported ONNX model says about itself: the ``metadata_props`` of its graph.

Torch-free on purpose: :mod:`torch_eigview.io.onnx` writes these properties and the
onnxruntime-only :mod:`torch_eigview.apps.predict` reads them back to validate its inputs.
Every value is a string (ONNX metadata is a string map); lists and shapes are JSON.

The file checksum (:mod:`torch_eigview.io.onnx_checksum`) catches corruption, not an edited
file whose checksum was appended again, nor a buggy writer. So the export also writes a
copy of the metadata into the graph itself (its ``doc_string``, :func:`graph_doc_string`),
and a reader (:meth:`OnnxModelInfo.from_model`) refuses metadata that differs from it (a
preprocessing record removed or changed, another image shape, other label names), naming
the entry, and
metadata that contradicts itself (duplicated label names, a preprocessing record of
another size or unit norm).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from torch_eigview.io.preprocessing import Preprocessing

__all__ = ["FORMAT", "FORMAT_VERSION", "KINDS", "OnnxModelInfo", "graph_doc_string"]

FORMAT = "torch_eigview.io.onnx"
# Version 2 added the copy of the metadata in the graph's doc_string; version 1 files are refused.
FORMAT_VERSION = 2
KINDS = ("projection", "recognizer")
# Every key torch_eigview writes; the graph's copy holds those present (a removed key differs).
_KEYS = (
    "format",
    "format_version",
    "kind",
    "module",
    "image_shape",
    "n_components",
    "unit_norm",
    "label_names",
    "reject",
    "preprocessing",
)
_DOC_PREFIX = "torch_eigview metadata "


def _ours(props: Mapping[str, str]) -> dict[str, str]:
    """torch_eigview's entries of ``props`` (others, such as the file checksum's, left out)."""
    return {key: props[key] for key in _KEYS if key in props}


def graph_doc_string(props: Mapping[str, str]) -> str:
    """The graph ``doc_string`` an export writes: a copy of torch_eigview's entries of
    ``props`` as JSON, to check the metadata against."""
    return _DOC_PREFIX + json.dumps(_ours(props), sort_keys=True)


@dataclass(frozen=True)
class OnnxModelInfo:
    """The metadata of an exported model.

    Attributes:
        kind: ``"projection"`` (images → coefficients) or ``"recognizer"`` (images →
            label index, pose, distance).
        image_shape: ``(C, H, W)`` of one input image; the graph's input is ``(B, C, H, W)``.
        n_components: k, the number of coefficients.
        unit_norm: whether the graph L2-normalizes each image before projecting.
        label_names: for a recognizer, the name of each label index (COIL: object ids as
            strings); empty for a projection.
        module: class name of the exported module (``EigenProjection``, ``KernelProjection``, …).
        reject: a recognizer with rejection thresholds: the graph has a fourth output,
            ``known`` (B,) bool. Absent from the metadata of older files (False).
        preprocessing: what turns an image file into the graph's input (size, channels,
            background), when the model was fitted from a manifest (``eigview fit``); None
            for a model that takes images of ``image_shape`` as they are.
    """

    kind: str
    image_shape: tuple[int, int, int]
    n_components: int
    unit_norm: bool
    label_names: tuple[str, ...] = ()
    module: str = ""
    reject: bool = False
    preprocessing: Preprocessing | None = None

    def to_props(self) -> dict[str, str]:
        """The ``metadata_props`` string map."""
        props = {
            "format": FORMAT,
            "format_version": str(FORMAT_VERSION),
            "kind": self.kind,
            "module": self.module,
            "image_shape": json.dumps(list(self.image_shape)),
            "n_components": str(self.n_components),
            "unit_norm": json.dumps(self.unit_norm),
            "label_names": json.dumps(list(self.label_names)),
            "reject": json.dumps(self.reject),
        }
        if self.preprocessing is not None:  # absent, not null: older readers see the same keys
            props["preprocessing"] = self.preprocessing.to_prop()
        return props

    @classmethod
    def from_props(cls, props: Mapping[str, str], source: str = "the model") -> OnnxModelInfo:
        """Parses ``metadata_props``; ``source`` (a file name) goes into error messages.

        Raises:
            ValueError: the model was not exported by torch_eigview, is of another format
                version, or its metadata is damaged.
        """
        if props.get("format") != FORMAT:
            raise ValueError(
                f"{source} was not exported by torch_eigview (metadata 'format' is "
                f"{props.get('format')!r}, expected {FORMAT!r}); export it with 'eigview export'"
            )
        if props.get("format_version") != str(FORMAT_VERSION):
            older = (
                " (version 1 held no copy of its metadata in the graph: export it again)"
                if props.get("format_version") == "1"
                else ""
            )
            raise ValueError(
                f"{source} has torch_eigview ONNX format version {props.get('format_version')!r}; "
                f"this torch_eigview reads version {FORMAT_VERSION}{older}"
            )
        try:
            kind = props["kind"]
            shape = json.loads(props["image_shape"])
            names = json.loads(props["label_names"])
            unit_norm = json.loads(props["unit_norm"])
            n_components = int(props["n_components"])
            reject = json.loads(props.get("reject", "false"))
            if not isinstance(reject, bool):
                raise ValueError(f"reject {reject!r} is not a bool")
            if kind not in KINDS:
                raise ValueError(f"kind {kind!r} is not one of {KINDS}")
            if not (
                isinstance(shape, list)
                and len(shape) == 3
                and all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in shape)
            ):
                raise ValueError(f"image_shape must be [C, H, W] of ints >= 1, got {shape!r}")
            if n_components < 1:
                raise ValueError(f"n_components must be >= 1, got {n_components}")
            if not (isinstance(names, list) and all(isinstance(v, str) for v in names)):
                raise ValueError(f"label_names must be a list of strings, got {names!r:.200}")
            repeated = sorted({v for v in names if names.count(v) > 1})
            if repeated:
                raise ValueError(
                    f"label_names must be distinct, one per label, got {repeated[:5]!r} more than once"
                )
            if kind == "recognizer" and not names:
                raise ValueError("label_names must name a recognizer's labels, got none")
            if not isinstance(unit_norm, bool):
                raise ValueError(f"unit_norm must be a bool, got {unit_norm!r}")
            prep = None
            if "preprocessing" in props:
                prep = Preprocessing.from_json(json.loads(props["preprocessing"]), "preprocessing")
                if prep.image_shape != tuple(shape):
                    raise ValueError(
                        f"preprocessing must give images of image_shape {shape}, got {list(prep.image_shape)}"
                    )
                if prep.unit_norm != unit_norm:
                    raise ValueError(
                        f"preprocessing must have the graph's unit_norm={unit_norm}, got {prep.unit_norm}"
                    )
        except (KeyError, ValueError) as exc:
            raise ValueError(f"{source} has damaged torch_eigview metadata: {exc}") from exc
        return cls(
            kind=kind,
            image_shape=(shape[0], shape[1], shape[2]),
            n_components=n_components,
            unit_norm=unit_norm,
            label_names=tuple(names),
            module=props.get("module", ""),
            reject=reject,
            preprocessing=prep,
        )

    @classmethod
    def from_model(cls, model: Any, source: str = "the model") -> OnnxModelInfo:
        """Parses the ``metadata_props`` of a loaded ``onnx.ModelProto`` (:meth:`from_props`)
        after checking them against the copy in its graph's ``doc_string``.

        Raises:
            ValueError: as :meth:`from_props`, or an entry differs from the graph's copy
                (edited, removed or added), or the graph holds no copy.
        """
        props = {p.key: p.value for p in model.metadata_props}
        info = cls.from_props(props, source)  # names a foreign or older file first
        doc = str(model.graph.doc_string)
        try:
            recorded = json.loads(doc[len(_DOC_PREFIX) :]) if doc.startswith(_DOC_PREFIX) else None
        except ValueError:
            recorded = None
        if not isinstance(recorded, dict):
            raise ValueError(
                f"{source}: the graph holds no copy of its metadata (doc_string {doc[:40]!r}): the file "
                "was edited or not written by torch_eigview; export it again"
            )
        ours = _ours(props)
        for key in _KEYS:
            if ours.get(key) != recorded.get(key):
                said = "absent" if key not in ours else repr(ours[key])
                want = "absent" if key not in recorded else repr(recorded[key])
                raise ValueError(
                    f"{source}: metadata entry {key!r} must be {want:.300} as the graph recorded it at "
                    f"export, got {said:.300}: the file was edited; export it again"
                )
        return info
