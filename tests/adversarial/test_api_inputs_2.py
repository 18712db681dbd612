"""Bad input to the Python API of this session's entry points for views (the view dataset,
masks, backgrounds, the foreground estimate, the preprocessing record): each must raise
ValueError or TypeError naming the argument, the constraint and the value, never another
exception, a hang or a silent result (manifests: test_manifest_inputs.py; the method:
test_api_inputs_3.py). Good input (``GOOD``) must be answered right.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from torch_eigview.datasets.background import BackgroundModel, check_masks, set_background
from torch_eigview.datasets.image_views import ViewDataset, read_view
from torch_eigview.datasets.manifest import ViewManifest
from torch_eigview.io.foreground import estimate_foreground
from torch_eigview.io.preprocessing import Preprocessing, prepare_array

from tests.adversarial import files, views
from tests.adversarial.harness import Case, Good, judge, outcome, params

IMAGES = torch.rand(2, 3, 8, 8, generator=torch.Generator().manual_seed(0))
MASKS = torch.ones(2, 1, 8, 8, dtype=torch.bool)


def _manifest(tmp: Path) -> ViewManifest:
    return ViewManifest.from_csv(views.manifest(tmp))


def _png(tmp: Path, name: str, array: np.ndarray) -> Path:
    return views.png(tmp / name, array)


def _image(tmp: Path) -> Path:
    return _png(tmp, "i.png", (np.random.default_rng(0).random((8, 8)) * 255).astype(np.uint8))


PREP = Preprocessing((8, 8), 1, background="auto")

VIEWS = [
    Case(
        "dataset-background-text",
        lambda t: ViewDataset(_manifest(t), background="auto"),
        r"background must be a BackgroundModel or None, got str",
    ),  # type: ignore[arg-type]
    Case("dataset-size-0", lambda t: ViewDataset(_manifest(t), (0, 8)), r"size\[0\] \(H\)=0 must be >= 1"),
    Case(
        "dataset-size-huge",
        lambda t: ViewDataset(_manifest(t), (100_000, 100_000)),
        r"size asks for 100000 pixels per image side, more than the limit of 512.*EIGVIEW_MAX_IMAGE_SIDE",
    ),
    Case(
        "dataset-size-float",
        lambda t: ViewDataset(_manifest(t), (8.5, 8)),  # type: ignore[arg-type]
        r"size\[0\] \(H\) must be an integer, got float 8\.5",
    ),
    Case(
        "dataset-channels-2",
        lambda t: ViewDataset(_manifest(t), channels=2),
        r"channels must be 1, 3 or None, got 2",
    ),
    Case(
        "dataset-dtype-int",
        lambda t: ViewDataset(_manifest(t), dtype=torch.int32),
        r"dtype must be a floating torch\.dtype",
    ),
    Case(
        "dataset-index-out-of-range",
        lambda t: ViewDataset(_manifest(t))[99],
        r"index=99 is out of range for 6 views",
        (IndexError, ValueError),
    ),
    Case(
        "read-mask-other-size",
        lambda t: read_view(
            _image(t), _png(t, "m.png", np.full((4, 4), 255, np.uint8)), background=BackgroundModel()
        ),
        r"mask .*m\.png has size \(H, W\)=\(4, 4\), its image .*i\.png \(8, 8\)",
    ),
    Case(
        "read-mask-all-false",
        lambda t: read_view(
            _image(t), _png(t, "m.png", np.zeros((8, 8), np.uint8)), background=BackgroundModel()
        ),
        r"i\.png: masks\[0\] is all background",
    ),
    Case(
        "read-rgba-empty-alpha",
        lambda t: read_view(_png(t, "a.png", np.zeros((8, 8, 4), np.uint8)), background=BackgroundModel()),
        r"a\.png: masks\[0\] is all background",
    ),
    Case(
        "read-background-leaves-nothing",
        lambda t: read_view(_image(t), background=BackgroundModel(background=(0.5,), tolerance=2.0)),
        r"i\.png: background=\(0\.5\).*leaves no object",
    ),
    Case(
        "read-mask-fifo", lambda t: read_view(_image(t), files.fifo(t / "m.png")), r"mask .*m\.png is a FIFO"
    ),
    Case("read-image-missing", lambda t: read_view(t / "none.png"), r"none\.png does not exist"),
    Case("read-size-0", lambda t: read_view(_image(t), size=(0, 4)), r"size\[0\] \(H\)=0 must be >= 1"),
    Case(
        "read-channels-4", lambda t: read_view(_image(t), channels=4), r"channels must be 1, 3 or None, got 4"
    ),
]

BACKGROUND = [
    Case(
        "model-colour-2",
        lambda t: BackgroundModel(background=(2.0, 0.0, 0.0)),
        r"background=\(2\.0, 0\.0, 0\.0\) must hold one value in \[0, 1\]",
    ),
    Case(
        "model-colour-nan",
        lambda t: BackgroundModel(background=(math.nan,)),
        r"background=\(nan,\) must hold one value in \[0, 1\]",
    ),
    Case(
        "model-colour-text",
        lambda t: BackgroundModel(background="black"),
        r"background must be a sequence of numbers or None, got 'black'",
    ),  # type: ignore[arg-type]
    Case(
        "model-colour-empty", lambda t: BackgroundModel(background=()), r"background=\(\) must hold one value"
    ),
    Case(
        "model-tolerance-negative",
        lambda t: BackgroundModel(tolerance=-0.1),
        r"tolerance=-0\.1 must be positive",
    ),
    Case(
        "model-tolerance-nan",
        lambda t: BackgroundModel(tolerance=math.nan),
        r"tolerance=nan must be positive \(a finite number",
    ),
    Case("model-fill-nan", lambda t: BackgroundModel(fill=math.nan), r"fill=nan must be a finite intensity"),
    Case(
        "model-fill-text", lambda t: BackgroundModel(fill="black"), r"fill must be a number, got str 'black'"
    ),  # type: ignore[arg-type]
    Case(
        "model-min-fraction-1",
        lambda t: BackgroundModel(min_fraction=1.0),
        r"min_fraction=1\.0 must lie in \[0, 1\)",
    ),
    Case(
        "model-min-fraction-negative",
        lambda t: BackgroundModel(min_fraction=-0.5),
        r"min_fraction=-0\.5 must lie in \[0, 1\)",
    ),
    Case("model-border-0", lambda t: BackgroundModel(border=0), r"border=0 must be >= 1"),
    Case(
        "model-colour-channels",
        lambda t: BackgroundModel(background=(0.1, 0.2)).masks(IMAGES),
        r"background=\(0\.1, 0\.2\) must hold C=3 values, one per channel",
    ),
    Case(
        "model-border-too-wide",
        lambda t: BackgroundModel(border=5).masks(IMAGES),
        r"border=5 must be less than half the image side min\(H, W\)=8",
    ),
    Case(
        "model-images-nan",
        lambda t: BackgroundModel().masks(torch.full((1, 1, 8, 8), math.nan)),
        r"images must be finite, got 64 NaN",
    ),
    Case(
        "model-images-3d",
        lambda t: BackgroundModel().masks(IMAGES[0]),
        r"images must have shape \(B, C, H, W\), got shape \(3, 8, 8\)",
    ),
    Case(
        "set-background-masks-shape",
        lambda t: set_background(IMAGES, MASKS[:, :, :4]),
        r"masks must have shape \(B, 1, H, W\) = \(2, 1, 8, 8\) to match the images, got \(2, 1, 4, 8\)",
    ),
    Case(
        "set-background-masks-float",
        lambda t: set_background(IMAGES, MASKS.float() * 0.5),
        r"masks must be a bool tensor .*got a tensor of dtype torch\.float32",
    ),
    Case(
        "set-background-value-nan",
        lambda t: set_background(IMAGES, MASKS, math.nan),
        r"value=nan must be a finite intensity",
    ),
    Case(
        "check-masks-batch",
        lambda t: check_masks(MASKS[:1], IMAGES),
        r"masks must have shape \(B, 1, H, W\) = \(2, 1, 8, 8\) to match the images, got \(1, 1, 8, 8\)",
    ),
    Case(
        "check-masks-int",
        lambda t: check_masks(MASKS.long() * 3, IMAGES),
        r"masks must be a bool tensor .*got a tensor of dtype torch\.int64",
    ),
    Case(
        "check-masks-numpy",
        lambda t: check_masks(np.ones((2, 1, 8, 8), bool), IMAGES),
        r"masks must be a (bool )?(torch\.)?[Tt]ensor",
    ),
    Case(
        "check-masks-all-false", lambda t: check_masks(MASKS & False, IMAGES), r"masks\[0\] is all background"
    ),
    Case("foreground-2d", lambda t: estimate_foreground(np.zeros((8, 8))), r"image must be \(C, H, W\)"),
    Case(
        "foreground-nan",
        lambda t: estimate_foreground(np.full((1, 8, 8), np.nan)),
        r"image must hold finite values, got NaN",
    ),
    Case(
        "foreground-empty",
        lambda t: estimate_foreground(np.zeros((1, 0, 0))),
        r"image .*(is empty|has no pixels|too small).*\(0, 0\)|image .*\(0, 0\).*(empty|no pixels|too small)",
    ),
    Case(
        "foreground-uniform",
        lambda t: estimate_foreground(np.full((1, 8, 8), 0.3)),
        r"background=\(0\.3\).*leaves no object in the image",
    ),
    Case(
        "foreground-colour-length",
        lambda t: estimate_foreground(np.zeros((3, 8, 8)), (0.1, 0.2)),
        r"background=\(0\.1, 0\.2\) must hold C=3 values, one per channel",
    ),
]

PREPROCESSING = [
    Case(
        "prep-size-tuple-of-floats",
        lambda t: Preprocessing((8.0, 8.0), 1),
        r"size must be \(H, W\) with ints >= 1, got \(8\.0, 8\.0\)",
    ),  # type: ignore[arg-type]
    Case(
        "prep-size-list",
        lambda t: Preprocessing([8, 8], 1),
        r"size must be \(H, W\) with ints >= 1, got \[8, 8\]",
    ),  # type: ignore[arg-type]
    Case("prep-channels-true", lambda t: Preprocessing((8, 8), True), r"channels must be 1 or 3, got True"),  # type: ignore[arg-type]
    Case(
        "prep-colour-with-keep",
        lambda t: Preprocessing((8, 8), 1, colour=(0.1,)),
        r"colour must be given with background='colour' and only then",
    ),
    Case(
        "prep-tolerance-with-keep",
        lambda t: Preprocessing((8, 8), 1, tolerance=0.1),
        r"tolerance goes with background 'auto' or 'colour'",
    ),
    Case(
        "prep-json-bool-size",
        lambda t: Preprocessing.from_json(
            {
                "size": [True, 8],
                "channels": 1,
                "background": "keep",
                "unit_norm": True,
                "resize": "bilinear-antialias",
            },
            "m.pt",
        ),
        r"m\.pt has a damaged preprocessing record: size must be .*\(True, 8\)",
    ),
    Case(
        "prep-json-size-3",
        lambda t: Preprocessing.from_json({"size": [8, 8, 8]}, "m.pt"),
        r"m\.pt has a damaged preprocessing record: size \[8, 8, 8\] is not \[H, W\]",
    ),
    Case(
        "prep-json-colour-text",
        lambda t: Preprocessing.from_json(
            {
                "size": [8, 8],
                "channels": 1,
                "background": "colour",
                "unit_norm": True,
                "resize": "bilinear-antialias",
                "colour": "red",
            },
            "m.pt",
        ),
        r"m\.pt .*colour 'red' is not a list",
    ),
    Case(
        "prepare-2d",
        lambda t: prepare_array(np.zeros((8, 8), np.float32), PREP),
        r"image must be \(C, H, W\) with C 1 or 3, got shape \(8, 8\)",
    ),
    Case(
        "prepare-mask-size",
        lambda t: prepare_array(np.zeros((1, 8, 8), np.float32), PREP, np.ones((4, 4), bool)),
        r"mask must have the image's size \(H, W\)=\(8, 8\), got \(4, 4\)",
    ),
    Case(
        "prepare-mask-all-false",
        lambda t: prepare_array(np.zeros((1, 8, 8), np.float32), PREP, np.zeros((8, 8), bool)),
        r"mask is all background",
    ),
    Case(
        "prepare-nan",
        lambda t: prepare_array(np.full((1, 8, 8), np.nan, np.float32), Preprocessing((8, 8), 1)),
        r"image must hold finite values in \[0, 1\], got min=.*nan",
    ),
    Case(
        "prepare-out-of-range",
        lambda t: prepare_array(np.full((1, 8, 8), 1e30, np.float32), Preprocessing((8, 8), 1)),
        r"image must hold finite values in \[0, 1\], got min=.*1e\+30",
    ),
    Case(
        "prepare-prep-dict",
        lambda t: prepare_array(np.zeros((1, 8, 8), np.float32), {"size": [8, 8]}),
        r"prep must be a Preprocessing",
    ),  # type: ignore[arg-type]
]

CASES = VIEWS + BACKGROUND + PREPROCESSING


def _dataset_item(out: ViewDataset, tmp: Path) -> bool:
    """Six views resized to (1, 8, 8), the first one the egg at 0 degrees, values in [0, 1]."""
    item = out[0]
    assert len(out) == 6 and (item["object"], item["azimuth"]) == ("egg", 0.0), item
    image = item["image"]
    assert image.shape == (1, 8, 8) and float(image.min()) >= 0 and float(image.max()) <= 1, image
    return True


def _square_masks(out: torch.Tensor, tmp: Path) -> bool:
    """A bright square on a uniform background: masks (B, 1, H, W), True on the square only."""
    expected = torch.zeros(2, 1, 8, 8, dtype=torch.bool)
    expected[..., 2:6, 2:6] = True
    assert out.dtype == torch.bool and torch.equal(out, expected), out
    return True


def _square() -> torch.Tensor:
    images = torch.full((2, 3, 8, 8), 0.2)
    images[..., 2:6, 2:6] = 0.9
    return images


def _prepared(out: np.ndarray, tmp: Path) -> bool:
    """A uniform (8, 8) gray image prepared at (4, 4): (1, 4, 4) float32 of the same gray."""
    assert out.shape == (1, 4, 4) and out.dtype == np.float32, (out.shape, out.dtype)
    assert np.allclose(out, 0.25, atol=1e-6), out
    return True


GOOD = [
    Good("dataset", lambda t: ViewDataset(_manifest(t), (8, 8)), _dataset_item),
    Good("background-masks", lambda t: BackgroundModel().masks(_square()), _square_masks),
    Good(
        "prepare-array",
        lambda t: prepare_array(np.full((1, 8, 8), 0.25, np.float32), Preprocessing((4, 4), 1)),
        _prepared,
    ),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what


@pytest.mark.parametrize("case", params(GOOD))
def test_good_input_is_answered_right(case: Good, tmp_path: Path) -> None:
    kind, what = judge(case, tmp_path)
    assert kind == "right", what
