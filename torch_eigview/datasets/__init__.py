"""Datasets: view manifests and their Dataset, COIL folders, the synthetic objects, their cameras and renderer, exact correspondences."""

from __future__ import annotations

from torch_eigview.datasets.backdrop import Backdrop
from torch_eigview.datasets.background import BackgroundModel, background_rule, set_background
from torch_eigview.datasets.cameras import (
    CAMERAS,
    AffineCamera,
    OrthographicCamera,
    PerspectiveCamera,
    make_camera,
)
from torch_eigview.datasets.coil import (
    DATA_ENV,
    CoilFolder,
    PoseStepWarning,
    find_coil_root,
    get_data_home,
    parse_object_spec,
)
from torch_eigview.datasets.correspondence import (
    ViewCorrespondence,
    exact_correspondence,
    exact_correspondence_2d,
    seen_error,
    view_correspondence,
)
from torch_eigview.datasets.image_views import ViewDataset, read_view
from torch_eigview.datasets.manifest import ViewEntry, ViewManifest
from torch_eigview.datasets.renderer import Render, render, render_views
from torch_eigview.datasets.scene import MASKS, SyntheticScene
from torch_eigview.datasets.seed_views import SeedViews, read_images, read_seed_views
from torch_eigview.datasets.shapes import SHAPES, SyntheticObject, make_object

__all__ = [
    "CAMERAS",
    "DATA_ENV",
    "MASKS",
    "SHAPES",
    "AffineCamera",
    "Backdrop",
    "BackgroundModel",
    "CoilFolder",
    "OrthographicCamera",
    "PerspectiveCamera",
    "PoseStepWarning",
    "Render",
    "SeedViews",
    "SyntheticObject",
    "SyntheticScene",
    "ViewCorrespondence",
    "ViewDataset",
    "ViewEntry",
    "ViewManifest",
    "background_rule",
    "exact_correspondence",
    "exact_correspondence_2d",
    "find_coil_root",
    "get_data_home",
    "make_camera",
    "make_object",
    "parse_object_spec",
    "read_images",
    "read_seed_views",
    "read_view",
    "render",
    "render_views",
    "seen_error",
    "set_background",
    "view_correspondence",
]
