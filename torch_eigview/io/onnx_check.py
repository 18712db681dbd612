"""A structural check of an exported ONNX recognizer before onnxruntime runs it, without torch.

``eigview predict`` runs files it did not write. A graph that passes this check is one
:mod:`torch_eigview.io.onnx` could have written: ``onnx.checker`` accepts it, it has the one
``images`` input (B, C, H, W) float32 of its metadata and the recognizer's three outputs
(four, with ``known``, when its metadata says it rejects), label indices that its label
names name one to one (:func:`check_graph_content`, which ``read_metadata`` runs too),
it uses only the operators our exports use (nothing that builds a tensor of a size read
from data: no ``Expand``, ``Tile``, ``ConstantOfShape``, ``Range``, ``Resize``, loops), its
weights are finite and its weights and per-image intermediate tensors (from ONNX shape
inference) fit in a byte budget, the ``max_model_bytes`` limit (2 GiB by default,
:mod:`torch_eigview.config`).
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from torch_eigview.config import get_config
from torch_eigview.io.onnx_metadata import OnnxModelInfo

__all__ = ["ALLOWED_OPS", "MODEL_BYTES", "check_graph_content", "check_recognizer_graph", "model_byte_limit"]

# The operators of every graph torch_eigview exports (linear and kernel recognizers, with
# and without unit norm, opsets 18 and later), and a few of the same kind (elementwise,
# reductions, reshapes) an exporter version might use instead.
ALLOWED_OPS = frozenset(
    {
        "Abs", "Add", "ArgMin", "Cast", "Clip", "Div", "Exp", "Gather", "GatherND", "Identity",
        "LessOrEqual",
        "MatMul", "Max", "Min", "Mul", "Neg", "Pow", "ReduceL2", "ReduceMax", "ReduceMin", "ReduceSum",
        "ReduceSumSquare", "Reshape", "Sqrt", "Squeeze", "Sub", "Transpose", "Unsqueeze",
    }
)  # fmt: skip
INPUT_NAME = "images"
OUTPUTS = ("label_index", "pose", "distance")
MODEL_BYTES = "max_model_bytes"  # the limit's name in torch_eigview.config
_BATCH = 64  # images per onnxruntime call in eigview predict: intermediates are held for as many


def model_byte_limit() -> int:
    """The byte budget: the ``max_model_bytes`` limit of :mod:`torch_eigview.config` (2 GiB
    by default; the ``eigview`` command reads ``EIGVIEW_MAX_MODEL_BYTES`` into it)."""
    return get_config()[MODEL_BYTES]


def _dims(value: Any) -> list[int | str]:
    return [d.dim_value if d.HasField("dim_value") else d.dim_param for d in value.type.tensor_type.shape.dim]


def _check_input(graph: Any, info: OnnxModelInfo, source: str) -> None:
    import onnx

    inputs = [i for i in graph.input if i.name not in {t.name for t in graph.initializer}]
    want = [INPUT_NAME, *info.image_shape]
    if len(inputs) != 1 or inputs[0].name != INPUT_NAME or _dims(inputs[0])[1:] != want[1:]:
        got = [(i.name, _dims(i)) for i in inputs]
        raise ValueError(
            f"{source} must have one input 'images' (B, {', '.join(map(str, info.image_shape))}) as its "
            f"metadata says, got {got}"
        )
    if inputs[0].type.tensor_type.elem_type != onnx.TensorProto.FLOAT:
        raise ValueError(f"{source} must take float32 images")


def _check_label_index(graph: Any, info: OnnxModelInfo, source: str) -> None:
    """The constant the ``label_index`` output gathers from: one index per gallery view,
    each within the label names, every name used (one per distinct label)."""
    from onnx import numpy_helper

    constants = {t.name: t for t in graph.initializer}
    producer = next((n for n in graph.node if "label_index" in n.output), None)
    table = None if producer is None or not producer.input else constants.get(producer.input[0])
    if table is None or table.data_location == 1:
        return  # not the form our exports have: onnxruntime's rows are checked per image
    values = numpy_helper.to_array(table)
    n_names = len(info.label_names)
    if values.dtype.kind not in "iu" or values.size == 0:
        raise ValueError(f"{source}: the label indices {table.name!r} must be integers, got {values.dtype}")
    used = np.unique(values)
    if used.min() < 0 or used.max() >= n_names or len(used) != n_names:
        raise ValueError(
            f"{source}: metadata entry 'label_names' must name every label index of the graph "
            f"({len(used)} distinct indices in [{used.min()}, {used.max()}]), got {n_names} names"
        )


def check_graph_content(graph: Any, info: OnnxModelInfo, source: str) -> None:
    """Checks a graph against its metadata: one input ``images`` (B, C, H, W) float32 of the
    metadata's ``image_shape``; for a recognizer, label indices matching ``label_names``.

    Raises:
        ValueError: a mismatch, naming ``source``.
    """
    _check_input(graph, info, source)
    if info.kind == "recognizer":
        _check_label_index(graph, info, source)


def _check_io(graph: Any, info: OnnxModelInfo, source: str) -> None:
    check_graph_content(graph, info, source)
    names = tuple(o.name for o in graph.output)
    expected = (*OUTPUTS, "known") if info.reject else OUTPUTS
    if names != expected:
        raise ValueError(f"{source} must have the outputs {expected} of a recognizer, got {names}")


def _check_weights(graph: Any, source: str, budget: int) -> None:
    """Sizes from the dims (external data never read), then finiteness of float weights."""
    from onnx import helper, numpy_helper

    total = 0
    for t in graph.initializer:
        itemsize = np.dtype(helper.tensor_dtype_to_np_dtype(t.data_type)).itemsize
        total += math.prod(t.dims) * itemsize
        if total > budget:
            raise ValueError(
                f"{source}'s weights exceed {budget} bytes at initializer {t.name!r} (dims {list(t.dims)}); "
                f"raise the limit with torch_eigview.config_context(max_model_bytes=...) or EIGVIEW_MAX_MODEL_BYTES"
            )
    for t in graph.initializer:
        if t.data_location == 1:  # EXTERNAL: onnxruntime loads and checks the folder itself
            continue
        arr = numpy_helper.to_array(t)
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            n_bad = int((~np.isfinite(arr)).sum())
            raise ValueError(
                f"{source} is damaged: initializer {t.name!r} holds {n_bad} NaN or infinite values"
            )


def _check_intermediates(model: Any, source: str, budget: int) -> None:
    """Every tensor's size per image, from strict shape inference, within the budget for a batch."""
    from onnx import shape_inference

    try:
        inferred = shape_inference.infer_shapes(model, strict_mode=True, data_prop=True)
    except Exception as exc:  # onnx raises InferenceError and others
        raise ValueError(f"{source} fails ONNX shape inference: {exc}") from exc
    per_image = budget // (4 * _BATCH)
    for value in [*inferred.graph.value_info, *inferred.graph.output]:
        dims = _dims(value)
        if any(isinstance(d, str) and d != "batch" for d in dims) or any(d == "" for d in dims):
            raise ValueError(f"{source}: tensor {value.name!r} has an unknown size {dims}")
        count = math.prod(d for d in dims if isinstance(d, int))
        if count > per_image:
            raise ValueError(
                f"{source}: tensor {value.name!r} of shape {dims} holds {count} values per image, more than "
                f"{per_image} ({budget} bytes for a batch of {_BATCH}); raise the limit with torch_eigview.config_context(max_model_bytes=...) or EIGVIEW_MAX_MODEL_BYTES"
            )


def check_recognizer_graph(path: str | os.PathLike[str], info: OnnxModelInfo) -> None:
    """Checks the graph of an exported recognizer before it is run (see the module's docstring).

    Args:
        path: the ``.onnx`` file (a regular file, already checked).
        info: its metadata, already parsed.

    Raises:
        ValueError: the file is larger than the budget, fails ``onnx.checker``, or its
            inputs, outputs, operators, weights or tensor sizes are not a recognizer's.
    """
    import onnx

    source = f"ONNX model {os.fspath(path)!r}"
    budget = model_byte_limit()
    size = os.stat(path).st_size
    if size > budget:
        raise ValueError(
            f"{source} is {size} bytes, more than {budget}; raise the limit with torch_eigview.config_context(max_model_bytes=...) or EIGVIEW_MAX_MODEL_BYTES"
        )
    try:
        model = onnx.load(os.fspath(path), load_external_data=False)
        onnx.checker.check_model(model)
    except Exception as exc:  # protobuf DecodeError, onnx ValidationError, ...
        raise ValueError(f"{source} is not a valid ONNX model: {exc}") from exc
    graph = model.graph
    ops = {(n.domain or "ai.onnx", n.op_type) for n in graph.node}
    foreign = sorted(f"{d}:{op}" for d, op in ops if d != "ai.onnx" or op not in ALLOWED_OPS)
    if foreign or len(model.functions):
        raise ValueError(
            f"{source} uses operators a torch_eigview recognizer never has: {foreign or 'local functions'} "
            f"(allowed: {', '.join(sorted(ALLOWED_OPS))})"
        )
    _check_io(graph, info, source)
    _check_weights(graph, source, budget)
    _check_intermediates(model, source, budget)
