"""torch_eigview: appearance eigenspaces from two or three views per object.

Novel-view warping (kornia), the sparse G·C form of the data matrix (torch.sparse), the
eigenspace (torch.linalg) and a frozen projection layer for training and ONNX export.

The top level holds the core names; everything else is imported from its subpackage
(``torch_eigview.geometry``, ``.warp``, ``.decomposition``, ``.nn``, ``.scale``, ``.io``,
``.datasets``; ``.apps`` holds the command line). Names are imported lazily (PEP 562):
``import torch_eigview`` alone does not import torch, so the torch-free parts
(``eigview predict``: onnxruntime inference) stay light.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from torch_eigview.environment import package_version
from torch_eigview.lazy import attach

if TYPE_CHECKING:
    from torch_eigview.config import config_context, get_config, set_config
    from torch_eigview.datasets.coil import CoilFolder
    from torch_eigview.decomposition.eigenspace import Eigenspace
    from torch_eigview.decomposition.kernel import KernelEigenspace
    from torch_eigview.decomposition.streaming import StreamingEigenspace
    from torch_eigview.environment import environment_info
    from torch_eigview.errors import NotFittedError
    from torch_eigview.geometry.correspondence import Correspondence
    from torch_eigview.geometry.flow import estimate_correspondence
    from torch_eigview.geometry.pose import affine_coefficients, estimate_elevation, orthographic_coefficients
    from torch_eigview.io.checkpoint import load_recognizer, save_recognizer
    from torch_eigview.method.estimator import FewViewEigenspace
    from torch_eigview.nn.kernel_projection import KernelProjection
    from torch_eigview.nn.projection import EigenProjection
    from torch_eigview.nn.recognition import NearestNeighborRecognizer
    from torch_eigview.synthesis import SynthesisOptions, SynthesizedViews, synthesize_views
    from torch_eigview.warp.novel_view import NovelViewWarp
    from torch_eigview.warp.operator import SparseViewOperator
    from torch_eigview.warp.perspective import PerspectiveWarp

__version__ = package_version()

# Public name -> the submodule that defines it.
_SOURCES = {
    "CoilFolder": "datasets.coil",
    "Correspondence": "geometry.correspondence",
    "EigenProjection": "nn.projection",
    "FewViewEigenspace": "method.estimator",
    "Eigenspace": "decomposition.eigenspace",
    "KernelEigenspace": "decomposition.kernel",
    "KernelProjection": "nn.kernel_projection",
    "NearestNeighborRecognizer": "nn.recognition",
    "NotFittedError": "errors",
    "NovelViewWarp": "warp.novel_view",
    "PerspectiveWarp": "warp.perspective",
    "SparseViewOperator": "warp.operator",
    "StreamingEigenspace": "decomposition.streaming",
    "SynthesisOptions": "synthesis",
    "SynthesizedViews": "synthesis",
    "affine_coefficients": "geometry.pose",
    "config_context": "config",
    "get_config": "config",
    "set_config": "config",
    "environment_info": "environment",
    "estimate_correspondence": "geometry.flow",
    "estimate_elevation": "geometry.pose",
    "load_recognizer": "io.checkpoint",
    "orthographic_coefficients": "geometry.pose",
    "save_recognizer": "io.checkpoint",
    "synthesize_views": "synthesis",
}

__all__ = [
    "CoilFolder",
    "Correspondence",
    "EigenProjection",
    "Eigenspace",
    "FewViewEigenspace",
    "KernelEigenspace",
    "KernelProjection",
    "NearestNeighborRecognizer",
    "NotFittedError",
    "NovelViewWarp",
    "PerspectiveWarp",
    "SparseViewOperator",
    "StreamingEigenspace",
    "SynthesisOptions",
    "SynthesizedViews",
    "affine_coefficients",
    "config_context",
    "environment_info",
    "estimate_correspondence",
    "estimate_elevation",
    "get_config",
    "load_recognizer",
    "orthographic_coefficients",
    "save_recognizer",
    "set_config",
    "synthesize_views",
]


__getattr__, __dir__ = attach(__name__, _SOURCES, __all__)
