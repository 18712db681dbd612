"""Bad input to the Python API of this session's entry points (views and masks, backgrounds,
preprocessing, rejection, the extent, the circle's overlap, the thread policy): each must
raise ValueError or TypeError naming the argument, the constraint and the value, never
another exception, a hang or a silent result (the manifests are in test_manifest_inputs.py).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from torch_eigview.apps.circle import synthesize_circle
from torch_eigview.datasets.background import BackgroundModel, check_masks, set_background
from torch_eigview.datasets.image_views import ViewDataset, read_view
from torch_eigview.datasets.manifest import ViewManifest
from torch_eigview.io.foreground import estimate_foreground
from torch_eigview.io.preprocessing import Preprocessing, prepare_array
from torch_eigview.method import FewViewEigenspace
from torch_eigview.method.rejection import calibrate_rejection
from torch_eigview.scale.thread_policy import for_products, idle_cpus, threads
from torch_eigview.synthesis import SynthesisOptions, synthesize_views
from torch_eigview.warp.normalize import resolve_extent

from tests.adversarial import files, views
from tests.adversarial.harness import Case, outcome

IMAGES = torch.rand(2, 3, 8, 8, generator=torch.Generator().manual_seed(0))
MASKS = torch.ones(2, 1, 8, 8, dtype=torch.bool)


def _seeds() -> torch.Tensor:
    """Two objects' seed views at 0 and 10 degrees (2, 2, 1, 32, 32), rendered."""
    images = views._rendered()
    return torch.stack(
        [
            torch.stack([torch.from_numpy(images[o, a] / 255.0).float()[None] for a in (0, 10)])
            for o in views.OBJECTS
        ]
    )


@functools.cache
def _fitted() -> FewViewEigenspace:
    return FewViewEigenspace(
        3, synth=(-10.0, 10.0, 5.0), reject_rate=0.1, reject_poses=(-10.0, 10.0, 2.5)
    ).fit(_seeds(), [0.0, 10.0])


def _fit(**params: object) -> object:
    return lambda t: FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0), **params).fit(_seeds(), [0.0, 10.0])


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
    Case("dataset-size-float", lambda t: ViewDataset(_manifest(t), (8.5, 8)), r"size.*8\.5"),  # type: ignore[arg-type]
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
    Case("model-colour-nan", lambda t: BackgroundModel(background=(math.nan,)), r"background.*nan"),
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
    Case("model-tolerance-nan", lambda t: BackgroundModel(tolerance=math.nan), r"tolerance.*nan"),
    Case("model-fill-nan", lambda t: BackgroundModel(fill=math.nan), r"fill=nan must be a finite intensity"),
    Case("model-fill-text", lambda t: BackgroundModel(fill="black"), r"fill.*'black'"),  # type: ignore[arg-type]
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
    Case("model-border-0", lambda t: BackgroundModel(border=0), r"border.*0"),
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
        r"images.*(finite|NaN)",
    ),
    Case(
        "model-images-3d", lambda t: BackgroundModel().masks(IMAGES[0]), r"images.*\(B, C, H, W\)|images.*4"
    ),
    Case(
        "set-background-masks-shape",
        lambda t: set_background(IMAGES, MASKS[:, :, :4]),
        r"masks.*\(2, 1, 8, 8\).*\(2, 1, 8, 4\)|masks.*shape",
    ),
    Case("set-background-masks-float", lambda t: set_background(IMAGES, MASKS.float() * 0.5), r"masks.*bool"),
    Case("set-background-value-nan", lambda t: set_background(IMAGES, MASKS, math.nan), r"value.*nan"),
    Case(
        "check-masks-batch",
        lambda t: check_masks(MASKS[:1], IMAGES),
        r"masks must have shape \(B, 1, H, W\) = \(2, 1, 8, 8\) to match the images, got \(1, 1, 8, 8\)",
    ),
    Case("check-masks-int", lambda t: check_masks(MASKS.long() * 3, IMAGES), r"masks.*(bool|0 and 1|binary)"),
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
        r"image.*(finite|NaN|nan)",
    ),
    Case(
        "foreground-empty",
        lambda t: estimate_foreground(np.zeros((1, 0, 0))),
        r"image.*(empty|0|too small|border)",
    ),
    Case("foreground-uniform", lambda t: estimate_foreground(np.full((1, 8, 8), 0.3)), r"leaves no object"),
    Case(
        "foreground-colour-length",
        lambda t: estimate_foreground(np.zeros((3, 8, 8)), (0.1, 0.2)),
        r"background.*(2|channels)",
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
        r"image.*(finite|NaN|nan)",
    ),
    Case(
        "prepare-out-of-range",
        lambda t: prepare_array(np.full((1, 8, 8), 1e30, np.float32), Preprocessing((8, 8), 1)),
        r"image.*\[0, 1\]",
    ),
    Case(
        "prepare-prep-dict",
        lambda t: prepare_array(np.zeros((1, 8, 8), np.float32), {"size": [8, 8]}),
        r"prep must be a Preprocessing",
    ),  # type: ignore[arg-type]
]

REJECTION = [
    Case("reject-rate-0", _fit(reject_rate=0.0), r"reject_rate=0\.0 must be a fraction in \(0, 1\)"),
    Case("reject-rate-1", _fit(reject_rate=1.0), r"reject_rate=1\.0 must be a fraction in \(0, 1\)"),
    Case("reject-rate-nan", _fit(reject_rate=math.nan), r"reject_rate=nan"),
    Case("reject-rate-text", _fit(reject_rate="5%"), r"reject_rate.*'5%'"),
    Case("reject-score-bogus", _fit(reject_rate=0.1, reject_score="euclid"), r"reject_score.*'euclid'"),
    Case(
        "reject-poses-reversed",
        _fit(reject_rate=0.1, reject_poses=(10.0, -10.0, 1.0)),
        r"reject_poses must have start <= stop",
    ),
    Case(
        "reject-poses-step-0",
        _fit(reject_rate=0.1, reject_poses=(-10.0, 10.0, 0.0)),
        r"reject_poses step must be positive",
    ),
    Case(
        "reject-poses-tiny-step",
        _fit(reject_rate=0.1, reject_poses=(-10.0, 10.0, 1e-9)),
        r"reject_poses asks for 2e\+10 views per object, more than the limit",
    ),
    Case(
        "reject-poses-gallery-only",
        _fit(reject_rate=0.1, reject_poses=(0.0, 0.0, 1.0)),
        r"reject_poses.*gallery",
    ),
    Case("reject-poses-nan", _fit(reject_rate=0.1, reject_poses=(math.nan, 10.0, 1.0)), r"reject_poses.*nan"),
    Case(
        "reject-poses-two-values",
        _fit(reject_rate=0.1, reject_poses=(0.0, 10.0)),
        r"reject_poses.*\(start, stop, step\)|reject_poses.*3",
    ),
    Case(
        "reject-without-synth",
        lambda t: FewViewEigenspace(3, synth=None, reject_rate=0.1).fit(_seeds(), [0.0, 10.0]),
        r"reject_rate=0\.1 calibrates on synthesized views: it needs synth",
    ),
    Case(
        "fit-masks-shape",
        lambda t: FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0)).fit(
            _seeds(), [0.0, 10.0], masks=torch.ones(2, 2, 16, 16, dtype=torch.bool)
        ),
        r"masks.*\(2, 2, 32, 32\)|masks.*shape",
    ),
    Case(
        "fit-masks-all-false",
        lambda t: FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0)).fit(
            _seeds(), [0.0, 10.0], masks=torch.zeros(2, 2, 32, 32, dtype=torch.bool)
        ),
        r"masks.*all background",
    ),
    Case(
        "fit-masks-float",
        lambda t: FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0)).fit(
            _seeds(), [0.0, 10.0], masks=torch.rand(2, 2, 32, 32)
        ),
        r"masks.*bool",
    ),
    Case(
        "calibrate-rate-nan",
        lambda t: calibrate_rejection(_fitted().recognizer_, _seeds()[0], math.nan),
        r"reject_rate=nan",
    ),
    Case(
        "calibrate-views-shape",
        lambda t: calibrate_rejection(_fitted().recognizer_, torch.rand(3, 1, 8, 8), 0.1),
        r"views must have shape \(B, 1024\) or \(B, \*\(1, 32, 32\)\) like the recognizer's gallery, got \(3, 1, 8, 8\)",
    ),
    Case(
        "calibrate-views-empty",
        lambda t: calibrate_rejection(_fitted().recognizer_, torch.rand(0, 1, 32, 32), 0.1),
        r"views.*(at least|empty|0 views|B=0)",
    ),
    Case(
        "calibrate-views-nan",
        lambda t: calibrate_rejection(_fitted().recognizer_, torch.full((3, 1, 32, 32), math.nan), 0.1),
        r"views.*(finite|NaN)",
    ),
    Case(
        "calibrate-score-bogus",
        lambda t: calibrate_rejection(_fitted().recognizer_, _seeds()[0], 0.1, "magic"),
        r"score.*'magic'",
    ),
    Case(
        "predict-reject-not-bool",
        lambda t: _fitted().recognizer_.predict(_seeds()[0], reject="yes"),
        r"reject must be a bool, got str",
    ),  # type: ignore[arg-type]
    Case(
        "predict-reject-uncalibrated",
        lambda t: (
            FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0))
            .fit(_seeds(), [0.0, 10.0])
            .predict(_seeds()[0], reject=True)
        ),
        r"reject.*(thresholds|calibrat)",
    ),
    Case(
        "set-rejection-nan",
        lambda t: _fitted().recognizer_.set_rejection(torch.tensor([math.nan, 0.1])),
        r"thresholds.*nan",
    ),
    Case(
        "set-rejection-negative",
        lambda t: _fitted().recognizer_.set_rejection(torch.tensor([-1.0, 0.1])),
        r"thresholds.*-1",
    ),
    Case(
        "set-rejection-shape",
        lambda t: _fitted().recognizer_.set_rejection(torch.tensor([0.1])),
        r"reject_thresholds must be \(t_dffs, t_difs\).*got shape \(1,\)",
    ),
]

SYNTHESIS = [
    Case(
        "options-extent-text",
        lambda t: SynthesisOptions(extent="yes"),
        r"extent must be True, False or 'auto', got 'yes'",
    ),
    Case(
        "options-extent-int",
        lambda t: SynthesisOptions(extent=1),
        r"extent must be True, False or 'auto', got 1",
    ),  # type: ignore[arg-type]
    Case(
        "resolve-extent-text",
        lambda t: resolve_extent("always", torch.ones(2, 8, 8, dtype=torch.bool)),
        r"extent.*'always'",
    ),
    Case("resolve-extent-masks-float", lambda t: resolve_extent("auto", torch.ones(2, 8, 8)), r"masks.*bool"),
    Case(
        "synth-masks-shape",
        lambda t: synthesize_views(_seeds()[0], 10.0, [5.0], masks=torch.ones(2, 16, 16, dtype=torch.bool)),
        r"masks.*\(2, 32, 32\)|masks.*shape",
    ),
    Case(
        "synth-masks-all-false",
        lambda t: synthesize_views(_seeds()[0], 10.0, [5.0], masks=torch.zeros(2, 32, 32, dtype=torch.bool)),
        r"masks.*all background",
    ),
    Case(
        "synth-masks-uint8",
        lambda t: synthesize_views(
            _seeds()[0], 10.0, [5.0], masks=torch.full((2, 32, 32), 7, dtype=torch.uint8)
        ),
        r"masks.*bool",
    ),
    Case(
        "circle-overlap-negative",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], 60.0, overlap=-5.0),
        r"overlap=-5 must be in \[0, alpha/2",
    ),
    Case(
        "circle-overlap-nan",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], 60.0, overlap=math.nan),
        r"overlap=nan",
    ),
    Case(
        "circle-overlap-past-alpha",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], 60.0, overlap=500.0),
        r"overlap=500 must be in \[0, alpha/2",
    ),
    Case(
        "circle-step-tiny",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], 1e-9),
        r"(step|circle step).*(limit|EIGVIEW_MAX_VIEWS)",
    ),
    Case(
        "circle-step-nan",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], math.nan),
        r"step.*nan",
    ),
    Case(
        "circle-two-seeds",
        lambda t: synthesize_circle(_seeds()[0], 10.0),
        r"seeds must hold M >= 3 views evenly spaced round the circle, got M=2",
    ),
]

THREADS = [
    Case("threads-0", lambda t: threads(0).__enter__(), r"n=0|threads.*0"),
    Case("threads-negative", lambda t: threads(-2).__enter__(), r"n=-2|threads.*-2"),
    Case("threads-text", lambda t: threads("2").__enter__(), r"n.*'2'|int"),  # type: ignore[arg-type]
    Case("threads-float", lambda t: threads(2.5).__enter__(), r"n.*2\.5"),  # type: ignore[arg-type]
    Case(
        "threads-huge",
        lambda t: threads(10**9).__enter__(),
        r"threads asks for 1e\+09 threads, more than the limit of 1024.*EIGVIEW_MAX_THREADS",
    ),
    Case("products-nan", lambda t: for_products(math.nan).__enter__(), r"flops=nan must be non-negative"),
    Case("products-negative", lambda t: for_products(-1.0).__enter__(), r"flops=-1\.0 must be non-negative"),
    Case("idle-interval-negative", lambda t: idle_cpus(-1.0), r"interval=-1\.0"),
    Case("idle-interval-nan", lambda t: idle_cpus(math.nan), r"interval=nan"),
    Case(
        "idle-interval-huge", lambda t: idle_cpus(1e9), r"interval=1000000000\.0 must be at most 60 seconds"
    ),
    Case(
        "idle-stat-fifo",
        lambda t: idle_cpus(0.01, stat=files.fifo(t / "stat")),
        r"stat='.*stat' must be a regular file",
    ),
]

CASES = VIEWS + BACKGROUND + PREPROCESSING + REJECTION + SYNTHESIS + THREADS


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what
