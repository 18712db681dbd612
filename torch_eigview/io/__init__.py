"""Input and output: checkpoints, ONNX export and its metadata, image reading and preprocessing.

Names are imported lazily (PEP 562): ``torch_eigview.io.images`` and
``torch_eigview.io.onnx_metadata`` need no torch, so ``eigview predict`` stays torch-free.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from torch_eigview.lazy import attach

if TYPE_CHECKING:
    from torch_eigview.io.checkpoint import load_recognizer, save_recognizer
    from torch_eigview.io.images import read_image
    from torch_eigview.io.model import Model, load_model
    from torch_eigview.io.onnx import (
        compare_with_eager,
        export_onnx,
        export_projection,
        export_recognizer,
        read_metadata,
    )
    from torch_eigview.io.onnx_metadata import OnnxModelInfo
    from torch_eigview.io.preprocessing import Preprocessing

_SOURCES = {
    "load_recognizer": "checkpoint",
    "save_recognizer": "checkpoint",
    "read_image": "images",
    "Model": "model",
    "load_model": "model",
    "compare_with_eager": "onnx",
    "export_onnx": "onnx",
    "export_projection": "onnx",
    "export_recognizer": "onnx",
    "read_metadata": "onnx",
    "OnnxModelInfo": "onnx_metadata",
    "Preprocessing": "preprocessing",
}

__all__ = [
    "Model",
    "OnnxModelInfo",
    "Preprocessing",
    "compare_with_eager",
    "export_onnx",
    "export_projection",
    "export_recognizer",
    "load_model",
    "load_recognizer",
    "read_image",
    "read_metadata",
    "save_recognizer",
]


__getattr__, __dir__ = attach(__name__, _SOURCES, __all__)
