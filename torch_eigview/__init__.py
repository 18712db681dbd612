"""torch_eigview: appearance eigenspaces from two or three views per object.

Novel-view warping (kornia), the sparse G·C form of the data matrix (torch.sparse), the
eigenspace (torch.linalg) and a frozen projection layer for training and ONNX export.

Public names are imported lazily (PEP 562): ``import torch_eigview`` alone does not import
torch, so the torch-free parts (``torch_eigview.predict``: onnxruntime inference) stay light.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from torch_eigview.cameras import affine_coefficients, estimate_elevation, orthographic_coefficients
    from torch_eigview.correspondence import (
        Correspondence,
        correspondence_from_disparity,
        estimate_correspondence,
    )
    from torch_eigview.data import CoilFolder, parse_object_spec
    from torch_eigview.distributed import fit_distributed
    from torch_eigview.eigenspace import Eigenspace
    from torch_eigview.errors import NotFittedError
    from torch_eigview.experiment import CoilExperiment, CoilResult
    from torch_eigview.io import load_recognizer, save_recognizer
    from torch_eigview.kernel import KernelEigenspace
    from torch_eigview.kernel_projection import KernelProjection
    from torch_eigview.normalize import foreground_mask, normalize_extent
    from torch_eigview.operator import SparseViewOperator
    from torch_eigview.parallel import synthesize_objects
    from torch_eigview.perspective import PerspectiveWarp
    from torch_eigview.projection import EigenProjection
    from torch_eigview.raster import invert_map_2d
    from torch_eigview.recognition import NearestNeighborRecognizer, Recognition
    from torch_eigview.streaming import StreamingEigenspace, blocks_of
    from torch_eigview.synthesis import SynthesisOptions, SynthesizedViews, synthesize_views
    from torch_eigview.synthetic import (
        AffineCamera,
        OrthographicCamera,
        PerspectiveCamera,
        exact_correspondence,
        exact_correspondence_2d,
        make_camera,
        make_object,
        render,
        render_views,
        view_correspondence,
    )
    from torch_eigview.trifocal import (
        novel_view_tensor,
        novel_view_tensor_from_cameras,
        transfer_points,
        trifocal_tensor,
    )
    from torch_eigview.view_cache import ViewCache
    from torch_eigview.warp import NovelViewWarp, WarpMaps

__version__ = "0.1.0"

# Public name -> the submodule that defines it.
_SOURCES = {
    "estimate_elevation": "cameras",
    "orthographic_coefficients": "cameras",
    "affine_coefficients": "cameras",
    "PerspectiveWarp": "perspective",
    "invert_map_2d": "raster",
    "trifocal_tensor": "trifocal",
    "novel_view_tensor": "trifocal",
    "novel_view_tensor_from_cameras": "trifocal",
    "transfer_points": "trifocal",
    "exact_correspondence_2d": "synthetic",
    "Correspondence": "correspondence",
    "correspondence_from_disparity": "correspondence",
    "estimate_correspondence": "correspondence",
    "CoilFolder": "data",
    "parse_object_spec": "data",
    "Eigenspace": "eigenspace",
    "NotFittedError": "errors",
    "CoilExperiment": "experiment",
    "CoilResult": "experiment",
    "load_recognizer": "io",
    "save_recognizer": "io",
    "KernelEigenspace": "kernel",
    "KernelProjection": "kernel_projection",
    "foreground_mask": "normalize",
    "normalize_extent": "normalize",
    "SparseViewOperator": "operator",
    "EigenProjection": "projection",
    "NearestNeighborRecognizer": "recognition",
    "Recognition": "recognition",
    "SynthesisOptions": "synthesis",
    "SynthesizedViews": "synthesis",
    "synthesize_views": "synthesis",
    "synthesize_objects": "parallel",
    "StreamingEigenspace": "streaming",
    "blocks_of": "streaming",
    "fit_distributed": "distributed",
    "AffineCamera": "synthetic",
    "OrthographicCamera": "synthetic",
    "PerspectiveCamera": "synthetic",
    "exact_correspondence": "synthetic",
    "make_camera": "synthetic",
    "make_object": "synthetic",
    "render": "synthetic",
    "render_views": "synthetic",
    "view_correspondence": "synthetic",
    "NovelViewWarp": "warp",
    "ViewCache": "view_cache",
    "WarpMaps": "warp",
}

__all__ = [
    "AffineCamera",
    "CoilExperiment",
    "CoilFolder",
    "CoilResult",
    "Correspondence",
    "EigenProjection",
    "Eigenspace",
    "KernelEigenspace",
    "KernelProjection",
    "NearestNeighborRecognizer",
    "NotFittedError",
    "NovelViewWarp",
    "OrthographicCamera",
    "PerspectiveCamera",
    "PerspectiveWarp",
    "Recognition",
    "SparseViewOperator",
    "StreamingEigenspace",
    "SynthesisOptions",
    "SynthesizedViews",
    "ViewCache",
    "WarpMaps",
    "affine_coefficients",
    "blocks_of",
    "correspondence_from_disparity",
    "estimate_correspondence",
    "estimate_elevation",
    "exact_correspondence",
    "exact_correspondence_2d",
    "fit_distributed",
    "foreground_mask",
    "invert_map_2d",
    "load_recognizer",
    "make_camera",
    "make_object",
    "normalize_extent",
    "novel_view_tensor",
    "novel_view_tensor_from_cameras",
    "orthographic_coefficients",
    "parse_object_spec",
    "render",
    "render_views",
    "save_recognizer",
    "synthesize_objects",
    "synthesize_views",
    "transfer_points",
    "trifocal_tensor",
    "view_correspondence",
]


def __getattr__(name: str) -> Any:
    """Imports a public name's submodule on first use (PEP 562) and caches the name."""
    source = _SOURCES.get(name)
    if source is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{source}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
