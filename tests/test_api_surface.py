"""The public API: a test that fails when a public name disappears (or appears unannounced)."""

from __future__ import annotations

import importlib
import importlib.metadata
from pathlib import Path

import pytest

import torch_eigview

PUBLIC = [
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

# Each subpackage's public names (its __all__).
SUBPACKAGES = {
    "method": [
        "ALL_COMPONENTS",
        "AROUND_SEEDS",
        "FewViewEigenspace",
        "MemoryBudgetError",
        "calibrate_rejection",
        "estimate_reject_rate",
        "resolve_components",
    ],
    "geometry": [
        "AffineCoefficients",
        "Correspondence",
        "affine_coefficients",
        "correspondence_from_disparity",
        "epipoles_from_tensor",
        "estimate_correspondence",
        "estimate_elevation",
        "fill_row_holes",
        "fundamental_from_tensor",
        "guided_tvl1",
        "invert_row_map",
        "match_rows",
        "novel_view_tensor",
        "novel_view_tensor_from_cameras",
        "orthographic_coefficients",
        "rotation_y",
        "seed_tensor",
        "tensor_from_fundamental",
        "transfer_points",
        "transform_tensor",
        "trifocal_tensor",
    ],
    "warp": [
        "BLENDS",
        "NovelViewWarp",
        "PerspectiveWarp",
        "RandomTurntableRotation",
        "SparseViewOperator",
        "WarpMaps",
        "foreground_mask",
        "invert_map_2d",
        "normalize_extent",
        "turntable_pose",
    ],
    "decomposition": [
        "BlockSource",
        "Eigenspace",
        "IncrementalEigenspace",
        "KernelEigenspace",
        "StreamingEigenspace",
        "blocks_of",
    ],
    "nn": [
        "EigenProjection",
        "KERNELS",
        "KernelProjection",
        "NearestNeighborRecognizer",
        "Recognition",
        "pairwise_kernel",
        "unit_rows",
    ],
    "scale": [
        "ViewCache",
        "available_cpus",
        "default_threads",
        "fit_distributed",
        "synthesize_objects",
        "threads",
    ],
    "io": [
        "Model",
        "OnnxModelInfo",
        "Preprocessing",
        "compare_with_eager",
        "export_onnx",
        "export_projection",
        "export_recognizer",
        "load_model",
        "load_recognizer",
        "read_image",
        "read_metadata",
        "save_recognizer",
    ],
    "datasets": [
        "AffineCamera",
        "Backdrop",
        "BackgroundModel",
        "CAMERAS",
        "CoilFolder",
        "DATA_ENV",
        "MASKS",
        "OrthographicCamera",
        "PerspectiveCamera",
        "PoseStepWarning",
        "Render",
        "SHAPES",
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
    ],
}


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


@pytest.mark.parametrize("subpackage", sorted(SUBPACKAGES))
def test_subpackage_surface(subpackage: str) -> None:
    module = importlib.import_module(f"torch_eigview.{subpackage}")
    assert sorted(module.__all__) == SUBPACKAGES[subpackage]
    missing = [name for name in module.__all__ if getattr(module, name, None) is None]
    assert not missing, f"torch_eigview.{subpackage} lacks {missing}"


def test_core_names_come_from_their_subpackage() -> None:
    """A top-level name is the same object as the one its subpackage exports."""
    for name in PUBLIC:
        homes = [s for s, names in SUBPACKAGES.items() if name in names]
        for s in homes:
            assert getattr(importlib.import_module(f"torch_eigview.{s}"), name) is getattr(
                torch_eigview, name
            )


def test_not_fitted_error_is_value_and_attribute_error() -> None:
    assert issubclass(torch_eigview.NotFittedError, ValueError)
    assert issubclass(torch_eigview.NotFittedError, AttributeError)


def test_py_typed_marker() -> None:
    assert (Path(torch_eigview.__file__).parent / "py.typed").is_file()


def test_version() -> None:
    assert isinstance(torch_eigview.__version__, str) and torch_eigview.__version__
    assert torch_eigview.__version__ == importlib.metadata.version("torch_eigview")
