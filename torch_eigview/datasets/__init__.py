"""Datasets: COIL folders and the synthetic renderer."""

from __future__ import annotations

from torch_eigview.datasets.coil import CoilFolder, parse_object_spec
from torch_eigview.datasets.renderer import (
    CAMERAS,
    AffineCamera,
    OrthographicCamera,
    PerspectiveCamera,
    Render,
    ViewCorrespondence,
    exact_correspondence,
    exact_correspondence_2d,
    make_camera,
    render,
    render_views,
    seen_error,
    view_correspondence,
)
from torch_eigview.datasets.shapes import SHAPES, SyntheticObject, make_object

__all__ = [
    "CAMERAS",
    "SHAPES",
    "AffineCamera",
    "CoilFolder",
    "OrthographicCamera",
    "PerspectiveCamera",
    "Render",
    "SyntheticObject",
    "ViewCorrespondence",
    "exact_correspondence",
    "exact_correspondence_2d",
    "make_camera",
    "make_object",
    "parse_object_spec",
    "render",
    "render_views",
    "seen_error",
    "view_correspondence",
]
