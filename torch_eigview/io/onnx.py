"""ONNX export of the projection layer and the whole recognizer, checked in onnxruntime.

The exporter is ``torch.onnx.export(..., dynamo=True)`` with a dynamic batch axis: the graph
takes ``images`` (B, C, H, W) float32 and gives ``coefficients`` (B, k) for a projection, or
``label_index``, ``pose`` and ``distance`` (B,) each for a recognizer, and ``known`` (B,)
bool for one with rejection thresholds. The graph's
``metadata_props`` describe it (:class:`~torch_eigview.io.onnx_metadata.OnnxModelInfo`), so the
torch-free ``eigview predict`` can check its inputs.

An :class:`EigenProjection` is exported in a folded form (:class:`FoldedProjection`), a
recognizer as :class:`ExportedRecognizer` (both in :mod:`torch_eigview.io.onnx_graphs`); any
other module on images (kernel PCA's ``KernelProjection``, an ``nn.Sequential`` of a
projection and a head) as it is. ``dynamo=False`` selects the TorchScript-based exporter.

This file is ``torch_eigview/io/onnx.py``: inside the package ``import onnx`` means the
onnx package (absolute imports); only running this file as a script would shadow it.
"""

from __future__ import annotations

import copy
import dataclasses
import io
import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from torch_eigview.check import check_float_tensor, check_int, check_ndim
from torch_eigview.files import atomic_output, check_output_path
from torch_eigview.io.onnx_check import check_graph_content
from torch_eigview.io.onnx_checksum import append_checksum, verify_checksum
from torch_eigview.io.onnx_graphs import (
    ExportedRecognizer,
    FoldedProjection,
    image_shape_of,
    projection_module,
)
from torch_eigview.io.onnx_metadata import OnnxModelInfo, graph_doc_string
from torch_eigview.io.preprocessing import Preprocessing
from torch_eigview.lazy import require
from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = [
    "ExportedRecognizer",
    "FoldedProjection",
    "compare_with_eager",
    "export_onnx",
    "export_projection",
    "export_recognizer",
    "read_metadata",
]

INPUT_NAME = "images"
PROJECTION_OUTPUTS = ("coefficients",)
RECOGNIZER_OUTPUTS = ("label_index", "pose", "distance")
MIN_OPSET = 18


class _Graph(nn.Module):
    """Holds the exported module one level down, so its constants are named ``model.<buffer>``
    and cannot collide with the graph's input and output names (a kernel layer's buffer
    called ``coefficients`` would otherwise clash with the output ``coefficients``)."""

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(self, x: torch.Tensor) -> Any:
        return self.model(x)


def _as_module(model: object) -> nn.Module:
    """A fitted estimator (``to_module()``) or a module; NotFittedError propagates."""
    if isinstance(model, nn.Module):
        return model
    to_module = getattr(model, "to_module", None)
    if callable(to_module):
        module = to_module()
        if isinstance(module, nn.Module):
            return module
    raise TypeError(
        "model must be an nn.Module with image_shape and n_components (EigenProjection, "
        f"KernelProjection, NearestNeighborRecognizer) or a fitted estimator, got {type(model).__name__}"
    )


def _input_shape(
    module: nn.Module, image_shape: object, example_input: object
) -> tuple[tuple[int, int, int], torch.Tensor | None]:
    """The (C, H, W) of the graph's images, from ``image_shape``, ``example_input`` or the
    module's own ``image_shape`` (all that are given must agree), and the example batch
    (float32, CPU) if given."""
    shapes: dict[str, tuple[int, ...]] = {}
    if image_shape is not None:
        if not isinstance(image_shape, (tuple, list, torch.Size)) or len(image_shape) != 3:
            raise TypeError(f"image_shape must be None or a (C, H, W) tuple of 3 ints, got {image_shape!r}")
        shapes["image_shape"] = tuple(check_int(v, "image_shape", minimum=1) for v in image_shape)
    example = None
    if example_input is not None:
        given = check_float_tensor(example_input, "example_input")
        check_ndim(given, "example_input", (4,), "(B, C, H, W)")
        if given.shape[0] < 1:
            raise ValueError(f"example_input must hold at least one image, got shape {tuple(given.shape)}")
        example = given.detach().to("cpu", torch.float32)
        shapes["example_input's (C, H, W)"] = tuple(example.shape[1:])
    if getattr(module, "image_shape", None) is not None or not shapes:
        shapes[f"{type(module).__name__}.image_shape"] = image_shape_of(module)
    if len(set(shapes.values())) > 1:
        raise ValueError("the image shapes differ: " + ", ".join(f"{k}={v}" for k, v in shapes.items()))
    c, h, w = next(iter(shapes.values()))
    return (c, h, w), example


def _sample(shape: tuple[int, int, int], example: torch.Tensor | None) -> torch.Tensor:
    """The batch the exporter traces: the example, else random images; two rows at least,
    since torch.export specializes a batch axis of size 1 to a constant."""
    if example is None:
        return torch.rand(2, *shape, generator=torch.Generator().manual_seed(0))
    return example if len(example) >= 2 else example.expand(2, *shape).contiguous()


def _prepare(
    model: object, fold: bool, image_shape: object, example_input: object
) -> tuple[nn.Module, OnnxModelInfo, tuple[str, ...], torch.Tensor]:
    module = _as_module(model)
    if isinstance(module, NearestNeighborRecognizer):
        recognizer = ExportedRecognizer(module).eval()
        info = OnnxModelInfo(
            kind="recognizer",
            image_shape=recognizer.image_shape,
            n_components=recognizer.n_components,
            unit_norm=recognizer.unit_norm,
            label_names=tuple(recognizer.label_names),
            module=type(module).__name__,
            reject=recognizer.rejects,
        )
        shape, example = _input_shape(module.projection, image_shape, example_input)
        outputs = (*RECOGNIZER_OUTPUTS, "known") if recognizer.rejects else RECOGNIZER_OUTPUTS
        return recognizer, info, outputs, _sample(shape, example)
    shape, example = _input_shape(module, image_shape, example_input)
    exported = projection_module(module, fold, torch.float32).eval()
    sample = _sample(shape, example)
    with torch.no_grad():
        out = exported(sample)
    if not isinstance(out, torch.Tensor) or out.ndim != 2:
        got = f"shape {tuple(out.shape)}" if isinstance(out, torch.Tensor) else type(out).__name__
        raise ValueError(
            f"{type(module).__name__} must map (B, C, H, W) images to one (B, k) tensor to be exported, got {got}"
        )
    info = OnnxModelInfo(
        kind="projection",
        image_shape=shape,
        n_components=int(out.shape[1]),
        unit_norm=any(getattr(m, "unit_norm", False) is True for m in module.modules()),
        module=type(module).__name__,
    )
    return exported, info, PROJECTION_OUTPUTS, sample


def export_onnx(
    model: object,
    path: str | os.PathLike[str],
    *,
    opset_version: int = MIN_OPSET,
    fold: bool = True,
    image_shape: tuple[int, int, int] | None = None,
    example_input: torch.Tensor | None = None,
    dynamo: bool = True,
    preprocessing: Preprocessing | None = None,
) -> OnnxModelInfo:
    """Exports a projection, a recognizer or any module on images to ONNX, with a dynamic batch axis.

    Args:
        model: an :class:`EigenProjection`, a :class:`NearestNeighborRecognizer`, any
            module mapping (B, C, H, W) images to one (B, k) tensor (kernel PCA's
            ``KernelProjection``, an ``nn.Sequential`` of a projection and a head), or a
            fitted estimator with ``to_module()``.
        path: the ``.onnx`` file to write; it is replaced atomically, and carries the
            SHA-256 of its contents (:mod:`torch_eigview.io.onnx_checksum`).
        opset_version: ONNX opset, at least 18.
        fold: export an :class:`EigenProjection` as :class:`FoldedProjection` (default);
            False exports its ``forward`` as written (Sub on the images, then MatMul; with
            ``unit_norm`` onnxruntime's one-pass ReduceL2 then costs some 5e-5 relative
            error on 128x128 images, see :class:`FoldedProjection`). A projection inside
            another module is exported as written.
        image_shape: (C, H, W) of the graph's input images; needed when the module has no
            ``image_shape`` of its own (an ``nn.Sequential``) and no ``example_input`` is given.
        example_input: (B, C, H, W) example images (B >= 1) to trace with; gives the image
            shape too. Default: random images of ``image_shape``.
        dynamo: True (default) uses the torch.export-based exporter; False the
            TorchScript-based one (the default of ``torch.onnx.export`` before torch 2.9).
        preprocessing: what turns an image file into the graph's input (recorded by
            ``eigview fit``), written into the metadata for ``eigview predict``; its
            ``image_shape`` must be the graph's.

    Returns:
        The metadata written into the graph's ``metadata_props``; ``n_components`` is the
        width k of the output.

    Raises:
        TypeError: ``model`` is not one of the above, or ``opset_version``, ``image_shape``
            or ``example_input`` has the wrong type.
        ValueError: the image shape is unknown or differs between ``image_shape``,
            ``example_input`` and the module's; the module's output is not (B, k); or
            ``opset_version`` is below 18 or above the installed onnx's newest opset; or
            ``path`` cannot be written (a directory, a
            special file, a missing folder).
        OSError: the write failed (disk full, file-size limit); ``path`` is unchanged.
        ImportError: onnx (or, with ``dynamo``, onnxscript) is not installed: the message
            names ``pip install 'torch_eigview[onnx]'``.
        NotFittedError: ``model`` is an estimator that was not fitted.
    """
    onnx = require("onnx", "onnx", "ONNX export")
    check_output_path(path, "path")
    if dynamo:
        require("onnxscript", "onnx", "ONNX export")
    # Above the installed onnx's newest opset the exporter would write another one silently.
    newest = onnx.defs.onnx_opset_version()
    opset_version = check_int(opset_version, "opset_version", minimum=MIN_OPSET, maximum=newest)
    if preprocessing is not None and not isinstance(preprocessing, Preprocessing):
        raise TypeError(f"preprocessing must be a Preprocessing or None, got {type(preprocessing).__name__}")
    module, info, outputs, sample = _prepare(model, fold, image_shape, example_input)
    if preprocessing is not None:
        if preprocessing.image_shape != info.image_shape:
            raise ValueError(
                f"preprocessing gives images (C, H, W)={preprocessing.image_shape}, but the model "
                f"takes {info.image_shape}"
            )
        info = dataclasses.replace(info, preprocessing=preprocessing)
    _save_graph(_Graph(module).eval(), sample, outputs, opset_version, dynamo, info.to_props(), path)
    return info


def _save_graph(
    graph: nn.Module,
    sample: torch.Tensor,
    outputs: tuple[str, ...],
    opset_version: int,
    dynamo: bool,
    props: dict[str, str],
    path: str | os.PathLike[str],
) -> None:
    """Exports ``graph`` traced on ``sample`` with a dynamic batch axis and writes it with ``props``."""
    names: dict[str, Any] = {
        "input_names": [INPUT_NAME],
        "output_names": list(outputs),
        "opset_version": opset_version,
    }
    if dynamo:
        batch = torch.export.Dim("batch")
        program = torch.onnx.export(graph, (sample,), dynamo=True, dynamic_shapes=({0: batch},), **names)
        if program is None:  # only with dynamo=False; keeps type checkers informed
            raise RuntimeError("torch.onnx.export returned no program")
        program.model.metadata_props.update(props)
        program.model.graph.doc_string = graph_doc_string(props)  # the metadata, checked on load
        with atomic_output(path) as tmp:
            # One file: weights as external data would escape the checksum and the atomic rename.
            program.save(tmp, external_data=False)
            append_checksum(tmp)
        return
    onnx = require("onnx", "onnx", "ONNX export")
    buffer = io.BytesIO()
    axes = {name: {0: "batch"} for name in (INPUT_NAME, *outputs)}
    torch.onnx.export(graph, (sample,), buffer, dynamo=False, dynamic_axes=axes, **names)  # type: ignore[arg-type]
    proto = onnx.load_from_string(buffer.getvalue())
    onnx.helper.set_model_props(proto, props)
    proto.graph.doc_string = graph_doc_string(props)
    with atomic_output(path) as tmp:
        onnx.save(proto, tmp)
        append_checksum(tmp)


def export_projection(
    projection: object,
    path: str | os.PathLike[str],
    *,
    opset_version: int = MIN_OPSET,
    fold: bool = True,
    dynamo: bool = True,
) -> OnnxModelInfo:
    """Exports a projection: images (B, C, H, W) float32 → coefficients (B, k). See :func:`export_onnx`."""
    if isinstance(projection, NearestNeighborRecognizer):
        projection = projection.projection
    return export_onnx(projection, path, opset_version=opset_version, fold=fold, dynamo=dynamo)


def export_recognizer(
    recognizer: NearestNeighborRecognizer,
    path: str | os.PathLike[str],
    *,
    opset_version: int = MIN_OPSET,
    dynamo: bool = True,
    preprocessing: Preprocessing | None = None,
) -> OnnxModelInfo:
    """Exports a recognizer: images (B, C, H, W) → label index, pose, distance. See :func:`export_onnx`."""
    if not isinstance(recognizer, NearestNeighborRecognizer):
        raise TypeError(f"recognizer must be a NearestNeighborRecognizer, got {type(recognizer).__name__}")
    return export_onnx(
        recognizer, path, opset_version=opset_version, dynamo=dynamo, preprocessing=preprocessing
    )


def read_metadata(path: str | os.PathLike[str]) -> OnnxModelInfo:
    """The :class:`OnnxModelInfo` of an exported file, after verifying its checksum and its
    content: the metadata as the graph recorded it at export
    (:meth:`OnnxModelInfo.from_model`), the graph's input of the metadata's image shape and,
    for a recognizer, label indices within its label names
    (:func:`~torch_eigview.io.onnx_check.check_graph_content`).

    Raises:
        ValueError: the file is missing, corrupted (checksum mismatch), not exported by
            torch_eigview, or its metadata was edited or contradicts the graph.
    """
    onnx = require("onnx", "onnx", "read_metadata")
    verify_checksum(path)
    model = onnx.load(os.fspath(path), load_external_data=False)
    source = f"ONNX model {os.fspath(path)!r}"
    info = OnnxModelInfo.from_model(model, source)
    check_graph_content(model.graph, info, source)
    return info


def compare_with_eager(
    model: nn.Module,
    path: str | os.PathLike[str],
    images: torch.Tensor,
    *,
    batch_size: int = 64,
    session: Any = None,
) -> dict[str, float]:
    """Runs the ONNX file in onnxruntime (CPU) and ``model`` eagerly on the same images.

    Arguments come in the order of :func:`export_onnx`: the module, then the file.

    Args:
        model: the module it was exported from (projection or recognizer).
        path: the exported file.
        images: (B, C, H, W) float32 images.
        batch_size: images per onnxruntime call.
        session: an ``onnxruntime.InferenceSession`` to reuse.

    Returns:
        For a projection ``max_rel_err``, ``max |onnx − eager| / max |eager|`` over the
        coefficients; for a recognizer ``label_agreement`` (the fraction of identical
        labels), ``max_pose_diff`` and ``max_distance_diff``, and with rejection
        ``known_agreement`` (the fraction of identical ``known`` answers). Distances come from
        ``|z|² − 2 z·g + |g|²`` (as in eager), which cancels near zero: in float32 a true
        distance of 0 reads up to about ``sqrt(1e-7 · |z|²)``, some 1e-4 for unit-norm views.
    """
    if isinstance(model, (str, os.PathLike)):
        raise TypeError(
            "compare_with_eager takes (model, path, images), the module first as export_onnx does; got "
            f"the path {os.fspath(model)!r} first: swap the first two arguments"
        )
    if not isinstance(images, torch.Tensor) or images.ndim != 4 or images.shape[0] == 0:
        shape = tuple(images.shape) if isinstance(images, torch.Tensor) else type(images).__name__
        raise ValueError(f"images must be a (B, C, H, W) tensor with B >= 1 to compare, got {shape}")
    if session is None:
        onnxruntime = require("onnxruntime", "onnx", "compare_with_eager")
        read_metadata(path)  # the checksum and the content, as eigview predict checks them
        session = onnxruntime.InferenceSession(os.fspath(path), providers=["CPUExecutionProvider"])
    x = images.detach().cpu().float()
    chunks: list[Sequence[np.ndarray]] = [
        session.run(None, {INPUT_NAME: x[i : i + batch_size].numpy()}) for i in range(0, len(x), batch_size)
    ]
    got = [np.concatenate([c[j] for c in chunks]) for j in range(len(chunks[0]))] if chunks else []
    model = copy.deepcopy(model).float().eval()  # .float() works in place: not on the caller's
    with torch.no_grad():
        if not isinstance(model, NearestNeighborRecognizer):
            return {"max_rel_err": _rel_err(got[0], model(x).numpy())}
        labels, poses, distances = (t.numpy() for t in model(x))
        values = model.labels.unique().numpy()
        out = {
            "label_agreement": float(np.mean(values[got[0]] == labels)) if len(x) else 1.0,
            "max_pose_diff": float(np.abs(got[1] - poses).max(initial=0.0)),
            "max_distance_diff": float(np.abs(got[2] - distances).max(initial=0.0)),
        }
        if model.rejects and len(got) == 4:
            known = (model.rejection_scores(x) <= 1).numpy()
            out["known_agreement"] = float(np.mean(got[3] == known)) if len(x) else 1.0
        return out


def _rel_err(got: np.ndarray, want: np.ndarray) -> float:
    scale = float(np.abs(want).max(initial=0.0))
    diff = float(np.abs(got.astype(np.float64) - want).max(initial=0.0))
    return diff / scale if scale > 0 else diff if math.isfinite(diff) else math.inf
