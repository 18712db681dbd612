"""The public API: a test that fails when a public name disappears (or appears unannounced)."""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import torch_eigview

PUBLIC = [
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


def test_all_is_the_documented_surface() -> None:
    assert len(torch_eigview.__all__) == len(set(torch_eigview.__all__)), "duplicates in __all__"
    assert set(torch_eigview.__all__) == set(PUBLIC)


def test_every_public_name_exists() -> None:
    missing = [name for name in PUBLIC if not hasattr(torch_eigview, name)]
    assert not missing, f"public names missing from torch_eigview: {missing}"
    for name in PUBLIC:
        assert getattr(torch_eigview, name) is not None


def test_star_import_gives_all() -> None:
    namespace: dict[str, object] = {}
    exec("from torch_eigview import *", namespace)
    assert set(namespace) - {"__builtins__"} == set(PUBLIC)


def test_not_fitted_error_is_value_and_attribute_error() -> None:
    assert issubclass(torch_eigview.NotFittedError, ValueError)
    assert issubclass(torch_eigview.NotFittedError, AttributeError)


def test_py_typed_marker() -> None:
    assert (Path(torch_eigview.__file__).parent / "py.typed").is_file()


def test_version() -> None:
    assert isinstance(torch_eigview.__version__, str) and torch_eigview.__version__
    assert torch_eigview.__version__ == importlib.metadata.version("torch_eigview")
