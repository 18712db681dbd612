"""What an exported ONNX model says about itself: the ``metadata_props`` of its graph.

Torch-free on purpose: :mod:`torch_eigview.io.onnx` writes these properties and the
onnxruntime-only :mod:`torch_eigview.apps.predict` reads them back to validate its inputs.
Every value is a string (ONNX metadata is a string map); lists and shapes are JSON.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass

from torch_eigview.io.preprocessing import Preprocessing

__all__ = ["FORMAT", "FORMAT_VERSION", "KINDS", "OnnxModelInfo"]

FORMAT = "torch_eigview.io.onnx"
FORMAT_VERSION = 1
KINDS = ("projection", "recognizer")


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
            raise ValueError(
                f"{source} has torch_eigview ONNX format version {props.get('format_version')!r}; "
                f"this torch_eigview reads version {FORMAT_VERSION}"
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
            if not (isinstance(shape, list) and len(shape) == 3 and all(isinstance(v, int) for v in shape)):
                raise ValueError(f"image_shape {shape!r} is not [C, H, W]")
            if not (isinstance(names, list) and all(isinstance(v, str) for v in names)):
                raise ValueError(f"label_names {names!r} is not a list of strings")
            if not isinstance(unit_norm, bool):
                raise ValueError(f"unit_norm {unit_norm!r} is not a bool")
            prep = None
            if "preprocessing" in props:
                prep = Preprocessing.from_json(json.loads(props["preprocessing"]), "preprocessing")
                if prep.image_shape != tuple(shape):
                    raise ValueError(f"preprocessing gives images {prep.image_shape}, image_shape is {shape}")
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
