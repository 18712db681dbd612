"""CoilExperiment's arguments (finite, bounded) and its handling of objects whose flow gives
no elevation: a warning naming the object, the untilted camera, and the run completes."""

from __future__ import annotations

import math
import warnings

import pytest
import torch

from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.synthesis import ElevationFallbackWarning, SynthesisOptions


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (dict(center=math.nan), ValueError, r"center=nan must be a finite number of degrees"),
        (dict(center="0"), TypeError, r"center must be a number"),
        (dict(synth=(math.nan, 20.0, 1.0)), ValueError, r"synth=\(nan, 20.0, 1.0\) must hold finite numbers"),
        (dict(synth=(-20.0, 20.0)), ValueError, r"synth must be \(start, stop, step\)"),
        (dict(test=(-45.0, math.inf)), ValueError, r"test=\(-45.0, inf\) must hold finite numbers"),
        (
            dict(synth=(-20.0, 20.0, 1e-9)),
            ValueError,
            r"synth asks for 4e\+10 views per object.*EIGVIEW_MAX_VIEWS",
        ),
        (dict(synth=(-20.0, 20.0, 0.0)), ValueError, r"synth step must be positive"),
        (dict(views="2"), ValueError, r"views must be 2 or 3, got '2'"),
        (dict(alpha=1e300), ValueError, r"alpha=1e\+300 must be an angle between seed views"),
    ],
)
def test_arguments(kwargs: dict[str, object], error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        CoilExperiment(**kwargs)  # type: ignore[arg-type]


def test_huge_center_is_wrapped_exactly() -> None:
    exp = CoilExperiment(center=1e9 + 0.5)
    assert exp._center == 1e9 + 0.5 - 360 * 2777778  # -79.5 (280.5 - 360), exact in float64
    assert CoilExperiment(center=-190.0)._center == 170.0 and CoilExperiment(center=180.0)._center == 180.0


@pytest.mark.slow
@pytest.mark.coil
def test_objects_without_an_elevation_fall_back(folder: CoilFolder) -> None:
    """Objects 5 (no trusted foreground match) and 7 (a fit saturated at 90 degrees) with
    alpha = 30 and ILK flow: the run completes, each named in a warning, elevation 0."""
    exp = CoilExperiment(alpha=30.0, objects=[5, 7], synthesis=SynthesisOptions(flow="ilk"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = exp.run(folder)
    messages = [str(w.message) for w in caught if issubclass(w.category, ElevationFallbackWarning)]
    assert any(m.startswith("object 5: seed pair 0") and "no trusted correspondence" in m for m in messages)
    assert any(m.startswith("object 7: seed pair 0") and "elevation=90" in m for m in messages)
    assert result.elevations == {5: [0.0], 7: [0.0]}
    assert math.isfinite(result.accuracy) and result.n_test == 2 * 19


@pytest.mark.slow
@pytest.mark.coil
def test_huge_center_runs_as_its_wrapped_angle(folder: CoilFolder) -> None:
    base = dict(method="sparse", objects=[1, 2], components=2)
    far = CoilExperiment(center=1e9, **base).run(folder)  # type: ignore[arg-type]
    wrapped = CoilExperiment(center=-80.0, **base).run(folder)  # type: ignore[arg-type]
    assert far.per_object == wrapped.per_object
    torch.testing.assert_close(far.recognizer.poses, wrapped.recognizer.poses)
