"""Frozen ``nn.Module`` layers: the eigenspace and kernel projections and the recognizer."""

from __future__ import annotations

from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.kernel_projection import KERNELS, KernelProjection, pairwise_kernel
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer, Recognition

__all__ = [
    "KERNELS",
    "EigenProjection",
    "KernelProjection",
    "NearestNeighborRecognizer",
    "Recognition",
    "pairwise_kernel",
    "unit_rows",
]
