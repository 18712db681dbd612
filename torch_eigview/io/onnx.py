"""ONNX export of the projection layer and the whole recognizer, checked in onnxruntime.

The exporter is ``torch.onnx.export(..., dynamo=True)`` with a dynamic batch axis: the graph
takes ``images`` (B, C, H, W) float32 and gives ``coefficients`` (B, k) for a projection, or
``label_index``, ``pose`` and ``distance`` (B,) each for a recognizer. The graph's
``metadata_props`` describe it (:class:`~torch_eigview.io.onnx_metadata.OnnxModelInfo`), so the
torch-free ``eigview predict`` can check its inputs.

An :class:`EigenProjection` is exported in a folded form, ``z = x @ Wᵀ − (mean @ Wᵀ)``
(:class:`FoldedProjection`), which is the same map with one MatMul on the images and a
(k,)-vector subtraction instead of a (B, N) one; ``mean @ Wᵀ`` is computed in float64 at
export time. Any other module with ``image_shape`` and ``n_components`` (kernel PCA's
``KernelProjection``) is exported as it is.

This file is ``torch_eigview/io/onnx.py``: inside the package ``import onnx`` means the
onnx package (absolute imports); only running this file as a script would shadow it.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from torch_eigview.check import check_int
from torch_eigview.io.onnx_metadata import OnnxModelInfo
from torch_eigview.nn.projection import EigenProjection
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


class FoldedProjection(nn.Module):
    """An :class:`EigenProjection` as one MatMul: ``z = x @ Wᵀ − b`` with ``b = mean @ Wᵀ``.

    With ``unit_norm`` the scale moves past the product: ``(x/|x|) @ Wᵀ = (x @ Wᵀ)/|x|``,
    a (B, k) division instead of a (B, N) one. Same map as the projection, up to rounding.
    Takes (B, C, H, W) images only (the exported graph's input).

    Args:
        projection: the fitted projection; needs ``image_shape``.
        dtype: dtype of the folded constants (and of the graph's input).
    """

    weight_t: torch.Tensor
    bias: torch.Tensor

    def __init__(self, projection: EigenProjection, dtype: torch.dtype = torch.float32) -> None:
        super().__init__()
        if not isinstance(projection, EigenProjection):
            raise TypeError(f"projection must be an EigenProjection, got {type(projection).__name__}")
        if projection.image_shape is None:
            raise ValueError("projection.image_shape is None: an image projection needs its (C, H, W)")
        self.image_shape = projection.image_shape
        self.unit_norm = projection.unit_norm
        w = projection.components.detach().cpu().double()
        # Contiguous (N, k): the MatMul needs no Transpose node; the bias in float64 so that
        # folding adds no rounding beyond the final cast.
        self.register_buffer("weight_t", w.T.contiguous().to(dtype))
        self.register_buffer("bias", (projection.mean.detach().cpu().double() @ w.T).to(dtype))

    @property
    def n_components(self) -> int:
        return self.weight_t.shape[1]

    def extra_repr(self) -> str:
        return f"image_shape={self.image_shape}, n_components={self.n_components}, unit_norm={self.unit_norm}"

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, C, H, W) images → (B, k) coefficients."""
        z = x.flatten(1) @ self.weight_t
        if self.unit_norm:
            # Two-stage sum of squares (rows, then the rest): onnxruntime's ReduceL2 sums the
            # N = C*H*W squares in one float32 run, 5e-5 off on 128x128 images; summing W,
            # then C*H values keeps the error near (W + C*H) eps, as good as torch's.
            sq = x.square().sum(dim=-1).flatten(1).sum(dim=1, keepdim=True)
            z = z / sq.sqrt().clamp_min(torch.finfo(x.dtype).tiny)
        return z - self.bias


class ExportedRecognizer(nn.Module):
    """A :class:`NearestNeighborRecognizer` in export form: images → (label index, pose, distance).

    The search is ``|z|² − 2 z·g + |g|²`` (MatMul), ReduceMin and ArgMin, then Gathers: no
    loops. Labels become indices into :attr:`label_names` (the recognizer's names, else its
    label values as strings, in sorted label order).
    """

    codes_t: torch.Tensor
    codes_sqnorm: torch.Tensor
    label_index: torch.Tensor
    poses: torch.Tensor

    def __init__(self, recognizer: NearestNeighborRecognizer, dtype: torch.dtype = torch.float32) -> None:
        super().__init__()
        if not isinstance(recognizer, NearestNeighborRecognizer):
            raise TypeError(
                f"recognizer must be a NearestNeighborRecognizer, got {type(recognizer).__name__}"
            )
        source = recognizer.projection
        self.image_shape = _image_shape(source)
        self.n_components = int(source.n_components)
        self.unit_norm = bool(getattr(source, "unit_norm", False))
        self.projection = _projection_module(source, fold=True, dtype=dtype)
        labels = recognizer.labels.detach().cpu()
        values = labels.unique()  # sorted
        self.label_names = list(recognizer.label_names or [str(v) for v in values.tolist()])
        codes = recognizer.codes.detach().cpu().double()
        self.register_buffer("codes_t", codes.T.contiguous().to(dtype))
        self.register_buffer("codes_sqnorm", codes.square().sum(dim=1).to(dtype))
        self.register_buffer("label_index", torch.searchsorted(values, labels))
        self.register_buffer("poses", recognizer.poses.detach().cpu().to(dtype))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(B, C, H, W) images → ``(label_index, pose, distance)``, each (B,)."""
        z = self.projection(x)
        sq = z.square().sum(dim=1, keepdim=True) - 2 * (z @ self.codes_t) + self.codes_sqnorm
        best, index = sq.min(dim=1)
        return self.label_index[index], self.poses[index], best.clamp_min(0).sqrt()


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


def _image_shape(module: nn.Module) -> tuple[int, int, int]:
    shape = getattr(module, "image_shape", None)
    if shape is None:
        raise ValueError(
            f"{type(module).__name__}.image_shape is None: the ONNX graph takes (B, C, H, W) images, "
            "so the (C, H, W) must be known (fit on images, or pass image_shape)"
        )
    c, h, w = (int(v) for v in shape)
    return c, h, w


def _projection_module(module: nn.Module, fold: bool, dtype: torch.dtype) -> nn.Module:
    """The module to export for a projection: folded for an EigenProjection, else a copy in ``dtype``."""
    if isinstance(module, EigenProjection) and fold:
        return FoldedProjection(module, dtype)
    return copy.deepcopy(module).to(dtype)


def _prepare(model: object, fold: bool) -> tuple[nn.Module, OnnxModelInfo, tuple[str, ...]]:
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
        )
        return recognizer, info, RECOGNIZER_OUTPUTS
    shape = _image_shape(module)
    n_components = check_int(getattr(module, "n_components", None), f"{type(module).__name__}.n_components")
    exported = _projection_module(module, fold, torch.float32).eval()
    info = OnnxModelInfo(
        kind="projection",
        image_shape=shape,
        n_components=n_components,
        unit_norm=bool(getattr(module, "unit_norm", False)),
        module=type(module).__name__,
    )
    return exported, info, PROJECTION_OUTPUTS


def export_onnx(
    model: object,
    path: str | os.PathLike[str],
    *,
    opset_version: int = MIN_OPSET,
    fold: bool = True,
) -> OnnxModelInfo:
    """Exports a projection or a recognizer to an ONNX file with a dynamic batch axis.

    Args:
        model: an :class:`EigenProjection`, a :class:`NearestNeighborRecognizer`, any
            module with ``image_shape`` (C, H, W) and ``n_components`` (e.g. kernel PCA's
            ``KernelProjection``), or a fitted estimator with ``to_module()``.
        path: the ``.onnx`` file to write.
        opset_version: ONNX opset, at least 18.
        fold: export an :class:`EigenProjection` as :class:`FoldedProjection` (default);
            False exports its ``forward`` as written (Sub on the images, then MatMul; with
            ``unit_norm`` onnxruntime's one-pass ReduceL2 then costs some 5e-5 relative
            error on 128x128 images, see :class:`FoldedProjection`).

    Returns:
        The metadata written into the graph's ``metadata_props``.

    Raises:
        TypeError: ``model`` is not one of the above, or ``opset_version`` not an integer.
        ValueError: ``image_shape`` is unknown or ``opset_version`` is below 18.
        NotFittedError: ``model`` is an estimator that was not fitted.
    """
    opset_version = check_int(opset_version, "opset_version", minimum=MIN_OPSET)
    module, info, outputs = _prepare(model, fold)
    sample = torch.rand(2, *info.image_shape, generator=torch.Generator().manual_seed(0))
    program = torch.onnx.export(
        _Graph(module).eval(),
        (sample,),
        dynamo=True,
        dynamic_shapes=({0: torch.export.Dim("batch")},),
        input_names=[INPUT_NAME],
        output_names=list(outputs),
        opset_version=opset_version,
        verbose=False,
    )
    if program is None:  # only with dynamo=False; keeps type checkers informed
        raise RuntimeError("torch.onnx.export returned no program")
    program.model.metadata_props.update(info.to_props())
    program.save(os.fspath(path))
    return info


def export_projection(
    projection: object, path: str | os.PathLike[str], *, opset_version: int = MIN_OPSET, fold: bool = True
) -> OnnxModelInfo:
    """Exports a projection: images (B, C, H, W) float32 → coefficients (B, k). See :func:`export_onnx`."""
    if isinstance(projection, NearestNeighborRecognizer):
        projection = projection.projection
    return export_onnx(projection, path, opset_version=opset_version, fold=fold)


def export_recognizer(
    recognizer: NearestNeighborRecognizer, path: str | os.PathLike[str], *, opset_version: int = MIN_OPSET
) -> OnnxModelInfo:
    """Exports a recognizer: images (B, C, H, W) → label index, pose, distance. See :func:`export_onnx`."""
    if not isinstance(recognizer, NearestNeighborRecognizer):
        raise TypeError(f"recognizer must be a NearestNeighborRecognizer, got {type(recognizer).__name__}")
    return export_onnx(recognizer, path, opset_version=opset_version)


def read_metadata(path: str | os.PathLike[str]) -> OnnxModelInfo:
    """The :class:`OnnxModelInfo` of an exported file (reads the graph, not the weights)."""
    import onnx

    model = onnx.load(os.fspath(path), load_external_data=False)
    props = {p.key: p.value for p in model.metadata_props}
    return OnnxModelInfo.from_props(props, source=os.fspath(path))


def compare_with_eager(
    path: str | os.PathLike[str],
    model: nn.Module,
    images: torch.Tensor,
    *,
    batch_size: int = 64,
    session: Any = None,
) -> dict[str, float]:
    """Runs the ONNX file in onnxruntime (CPU) and ``model`` eagerly on the same images.

    Args:
        path: the exported file.
        model: the module it was exported from (projection or recognizer).
        images: (B, C, H, W) float32 images.
        batch_size: images per onnxruntime call.
        session: an ``onnxruntime.InferenceSession`` to reuse.

    Returns:
        For a projection ``max_rel_err``, max |onnx − eager| / max |eager| over the
        coefficients; for a recognizer ``label_agreement`` (the fraction of identical
        labels), ``max_pose_diff`` and ``max_distance_diff``. Distances come from
        ``|z|² − 2 z·g + |g|²`` (as in eager), which cancels near zero: in float32 a true
        distance of 0 reads up to about ``sqrt(1e-7 · |z|²)``, some 1e-4 for unit-norm views.
    """
    import onnxruntime

    if not isinstance(images, torch.Tensor) or images.ndim != 4 or images.shape[0] == 0:
        shape = tuple(images.shape) if isinstance(images, torch.Tensor) else type(images).__name__
        raise ValueError(f"images must be a (B, C, H, W) tensor with B >= 1 to compare, got {shape}")
    if session is None:
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
        return {
            "label_agreement": float(np.mean(values[got[0]] == labels)) if len(x) else 1.0,
            "max_pose_diff": float(np.abs(got[1] - poses).max(initial=0.0)),
            "max_distance_diff": float(np.abs(got[2] - distances).max(initial=0.0)),
        }


def _rel_err(got: np.ndarray, want: np.ndarray) -> float:
    scale = float(np.abs(want).max(initial=0.0))
    diff = float(np.abs(got.astype(np.float64) - want).max(initial=0.0))
    return diff / scale if scale > 0 else diff if math.isfinite(diff) else math.inf
