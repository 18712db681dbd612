"""The modules in the form they are exported to ONNX, and what export needs to know of a module.

:class:`FoldedProjection` is an :class:`EigenProjection` folded into one MatMul on the
images, ``z = x @ Wᵀ − (mean @ Wᵀ)``: the same map with a (k,)-vector subtraction instead of
a (B, N) one, ``mean @ Wᵀ`` computed in float64 at export time. :class:`ExportedRecognizer`
is a :class:`NearestNeighborRecognizer` as a loop-free graph (with a fourth output,
``known``, when the recognizer has rejection thresholds). Any other module (kernel PCA's
``KernelProjection``, an ``nn.Sequential`` of a projection and a head) is exported as it is.
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer
from torch_eigview.nn.rejection import rejection_score

__all__ = ["ExportedRecognizer", "FoldedProjection", "image_shape_of", "projection_module"]


def image_shape_of(module: nn.Module) -> tuple[int, int, int]:
    """The (C, H, W) a module takes; ValueError when it has none."""
    shape = getattr(module, "image_shape", None)
    if shape is None:
        raise ValueError(
            f"{type(module).__name__}.image_shape is None: the ONNX graph takes (B, C, H, W) images, "
            "so the (C, H, W) must be known (fit on images, or pass image_shape=(C, H, W) or "
            "example_input=(B, C, H, W) images to export_onnx)"
        )
    c, h, w = (int(v) for v in shape)
    return c, h, w


def projection_module(module: nn.Module, fold: bool, dtype: torch.dtype) -> nn.Module:
    """The module to export for a projection: folded for an EigenProjection, else a CPU copy in ``dtype``."""
    if isinstance(module, EigenProjection) and fold:
        return FoldedProjection(module, dtype)
    return copy.deepcopy(module).to("cpu", dtype)


class FoldedProjection(nn.Module):
    """An :class:`EigenProjection` as one MatMul: ``z = x @ Wᵀ − b`` with ``b = mean @ Wᵀ``.

    With ``unit_norm`` the view is divided by its largest magnitude first (so that its
    squares neither overflow nor underflow at any scale, as :func:`~torch_eigview.nn.unit_rows`
    does) and the norm moves past the product: ``(v/|v|) @ Wᵀ = (v @ Wᵀ)/|v|``. Same map as
    the projection, up to rounding.
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
        if not self.unit_norm:
            return x.flatten(1) @ self.weight_t - self.bias
        tiny = torch.finfo(x.dtype).tiny
        x = x / x.flatten(1).abs().amax(dim=1).clamp_min(tiny).view(-1, 1, 1, 1)
        z = x.flatten(1) @ self.weight_t
        # Two-stage sum of squares (rows, then the rest): onnxruntime's ReduceL2 sums the
        # N = C*H*W squares in one float32 run, 5e-5 off on 128x128 images; summing W,
        # then C*H values keeps the error near (W + C*H) eps, as good as torch's.
        sq = x.square().sum(dim=-1).flatten(1).sum(dim=1, keepdim=True)
        return z / sq.sqrt().clamp_min(tiny) - self.bias


class ExportedRecognizer(nn.Module):
    """A :class:`NearestNeighborRecognizer` in export form: images → (label index, pose, distance).

    The search is ``|z|² − 2 z·g + |g|²`` (MatMul), ReduceMin and ArgMin, then Gathers: no
    loops. Labels become indices into :attr:`label_names` (the recognizer's names, else its
    label values as strings, in sorted label order). With rejection thresholds a fourth
    output, ``known`` (B,) bool, applies them; the distance from feature space is then
    ``|v|² − 2 v·mean + |mean|² − |z|²`` on the images (``v`` unit-norm when the layer is).
    """

    codes_t: torch.Tensor
    codes_sqnorm: torch.Tensor
    label_index: torch.Tensor
    poses: torch.Tensor
    reject_inverse: torch.Tensor
    mean: torch.Tensor
    mean_sqnorm: torch.Tensor

    def __init__(self, recognizer: NearestNeighborRecognizer, dtype: torch.dtype = torch.float32) -> None:
        super().__init__()
        if not isinstance(recognizer, NearestNeighborRecognizer):
            raise TypeError(
                f"recognizer must be a NearestNeighborRecognizer, got {type(recognizer).__name__}"
            )
        source = recognizer.projection
        self.image_shape = image_shape_of(source)
        self.n_components = int(source.n_components)
        self.unit_norm = bool(getattr(source, "unit_norm", False))
        self.projection = projection_module(source, fold=True, dtype=dtype)
        labels = recognizer.labels.detach().cpu()
        values = labels.unique()  # sorted
        self.label_names = list(recognizer.label_names or [str(v) for v in values.tolist()])
        codes = recognizer.codes.detach().cpu().double()
        self.register_buffer("codes_t", codes.T.contiguous().to(dtype))
        self.register_buffer("codes_sqnorm", codes.square().sum(dim=1).to(dtype))
        self.register_buffer("label_index", torch.searchsorted(values, labels))
        self.register_buffer("poses", recognizer.poses.detach().cpu().to(dtype))
        self.rejects = recognizer.rejects
        thresholds = recognizer.reject_thresholds.detach().cpu().double()
        self.uses_dffs = self.rejects and bool(torch.isfinite(thresholds[0]))
        self.register_buffer("reject_inverse", (1 / thresholds).to(dtype))  # finite: 0 for inf
        if self.uses_dffs:
            assert isinstance(source, EigenProjection)  # set_rejection allows a finite t_dffs only then
            mean = source.mean.detach().cpu().double()
            self.register_buffer("mean", mean.to(dtype))
            self.register_buffer("mean_sqnorm", mean.square().sum().to(dtype))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """(B, C, H, W) images → ``(label_index, pose, distance)``, each (B,), and ``known``
        (B,) bool when the recognizer rejects."""
        z = self.projection(x)
        sq = z.square().sum(dim=1, keepdim=True) - 2 * (z @ self.codes_t) + self.codes_sqnorm
        best, index = sq.min(dim=1)
        difs = best.clamp_min(0).sqrt()
        if not self.rejects:
            return self.label_index[index], self.poses[index], difs
        # difs * 0, not zeros_like: that exports as Shape and Expand, which onnx_check refuses.
        dffs = self._dffs(x, z) if self.uses_dffs else difs * 0
        known = rejection_score(dffs, difs, self.reject_inverse) <= 1
        return self.label_index[index], self.poses[index], difs, known

    def _dffs(self, x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        flat = x.flatten(1)
        if self.unit_norm:  # the unit vector, scaled first as the projection's
            flat = unit_rows(flat)
        dot = flat @ self.mean
        sq = flat.square().sum(dim=1)
        return (sq - 2 * dot + self.mean_sqnorm - z.square().sum(dim=1)).clamp_min(0).sqrt()
