"""torch_eigview: appearance eigenspaces from two or three views per object.

Novel-view warping (kornia), the sparse G·C form of the data matrix (torch.sparse), the
eigenspace (torch.linalg) and a frozen projection layer for training and ONNX export.
"""

from torch_eigview.cameras import estimate_elevation, orthographic_coefficients
from torch_eigview.correspondence import (
    Correspondence,
    correspondence_from_disparity,
    estimate_correspondence,
)
from torch_eigview.data import CoilFolder, parse_object_spec
from torch_eigview.eigenspace import Eigenspace
from torch_eigview.errors import NotFittedError
from torch_eigview.experiment import CoilExperiment, CoilResult
from torch_eigview.io import load_recognizer, save_recognizer
from torch_eigview.normalize import foreground_mask, normalize_extent
from torch_eigview.operator import SparseViewOperator
from torch_eigview.projection import EigenProjection
from torch_eigview.recognition import NearestNeighborRecognizer, Recognition
from torch_eigview.synthesis import SynthesisOptions, SynthesizedViews, synthesize_views
from torch_eigview.warp import NovelViewWarp, WarpMaps

__version__ = "0.1.0"

__all__ = [
    "CoilExperiment",
    "CoilFolder",
    "CoilResult",
    "Correspondence",
    "EigenProjection",
    "Eigenspace",
    "NearestNeighborRecognizer",
    "NotFittedError",
    "NovelViewWarp",
    "Recognition",
    "SparseViewOperator",
    "SynthesisOptions",
    "SynthesizedViews",
    "WarpMaps",
    "correspondence_from_disparity",
    "estimate_correspondence",
    "estimate_elevation",
    "foreground_mask",
    "load_recognizer",
    "normalize_extent",
    "orthographic_coefficients",
    "parse_object_spec",
    "save_recognizer",
    "synthesize_views",
]
