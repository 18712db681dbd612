"""Tests for the COIL experiment: angle helpers, the three methods on 3 objects, errors."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
import torch

from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.evaluation.coil import CoilExperiment, CoilResult, angle_range, wrap_degrees
from torch_eigview.synthesis import SynthesisOptions

OBJECTS = [1, 2, 3]
ALPHA = 10.0
TEST = (-10.0, 10.0)
JSON_KEYS = {"accuracy", "per_object", "pose_mae_deg", "pose_error_deg", "n_test", "n_train_views", "seconds"}
SECONDS_KEYS = {"correspondence", "synthesis", "eigen", "recognition", "total"}

# Short ranges and 3 components keep the whole module at a few seconds; elevation 0 skips
# the 2D refinement of the tilted camera, the costliest part of the synthesis.
_NVS = CoilExperiment(
    alpha=ALPHA,
    synth=(-5.0, 10.0, 5.0),
    test=TEST,
    components=3,
    method="nvs",
    objects=OBJECTS,
    synthesis=SynthesisOptions(elevation=0.0),
)
CONFIGS: dict[str, CoilExperiment] = {
    "nvs": _NVS,
    # Three seeds at 0, 10, 20: the synthesized range follows them, -5..20 every 5 degrees.
    "nvs3": dataclasses.replace(_NVS, views=3),
    "sparse": CoilExperiment(alpha=ALPHA, test=TEST, components=3, method="sparse", objects=OBJECTS),
    "sparse3": CoilExperiment(
        alpha=ALPHA, views=3, test=TEST, components=3, method="sparse", objects=OBJECTS
    ),
    # The dense baseline takes the real views every 5 degrees whatever the synth step.
    "dense": CoilExperiment(
        alpha=ALPHA, synth=(-10.0, 10.0, 1.0), test=TEST, components=3, method="dense", objects=OBJECTS
    ),
}


def expected_train_views(exp: CoilExperiment) -> int:
    n_obj = len(OBJECTS)
    # The range spelled out here, not read back from the experiment: synth, its stop moved
    # by alpha for the third seed.
    start, stop, step = exp.synth
    stop += (exp.views - 2) * exp.alpha
    if exp.method == "nvs":
        return n_obj * len(angle_range(start, stop, step, name="synth"))
    if exp.method == "sparse":
        return n_obj * exp.views
    return n_obj * len(angle_range(start, stop, 5.0, name="synth"))


@pytest.fixture(scope="module")
def results(folder: CoilFolder) -> dict[str, CoilResult]:
    return {name: exp.run(folder) for name, exp in CONFIGS.items()}


# --------------------------------------------------------------------------- helpers
def test_angle_range() -> None:
    assert angle_range(-5.0, 10.0, 5.0, "synth") == [-5.0, 0.0, 5.0, 10.0]
    assert angle_range(0.0, 0.0, 1.0, "synth") == [0.0]
    assert angle_range(0.0, 9.0, 5.0, "synth") == [0.0, 5.0]  # stop is not reached exactly
    tenths = angle_range(0.0, 0.3, 0.1, "synth")  # 0.3 / 0.1 is 2.9999999999999996 in floats
    assert len(tenths) == 4 and tenths[-1] == pytest.approx(0.3)
    assert len(angle_range(-20.0, 20.0, 1.0, "synth")) == 41


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((0.0, 10.0, 0.0), "synth step must be positive, got 0.0"),
        ((0.0, 10.0, -5.0), "synth step must be positive, got -5.0"),
        ((0.0, 10.0, float("nan")), "synth step must be positive"),
        ((10.0, 0.0, 5.0), "synth must have start <= stop, got start=10.0, stop=0.0"),
    ],
)
def test_angle_range_errors(args: tuple[float, float, float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        angle_range(*args, name="synth")


def test_wrap_degrees() -> None:
    angles = torch.tensor([0.0, 180.0, -180.0, 190.0, -190.0, 360.0, 540.0, 359.0, -45.0, 725.0])
    want = torch.tensor([0.0, 180.0, 180.0, -170.0, 170.0, 0.0, 180.0, -1.0, -45.0, 5.0])
    torch.testing.assert_close(wrap_degrees(angles), want, atol=1e-5, rtol=0)
    wrapped = wrap_degrees(torch.linspace(-1000.0, 1000.0, 2001, dtype=torch.float64))
    assert bool((wrapped > -180).all() and (wrapped <= 180).all())
    # Same angle modulo 360.
    diff = torch.remainder(wrapped - torch.linspace(-1000.0, 1000.0, 2001, dtype=torch.float64), 360)
    assert bool(((diff < 1e-9) | (diff > 360 - 1e-9)).all())


# --------------------------------------------------------------------------- runs
@pytest.mark.coil
@pytest.mark.parametrize("name", list(CONFIGS))
def test_result_record(results: dict[str, CoilResult], name: str) -> None:
    exp, result = CONFIGS[name], results[name]
    n_test_angles = len(angle_range(TEST[0], TEST[1], 5.0, "test"))
    assert 0.0 <= result.accuracy <= 100.0
    assert list(result.per_object) == OBJECTS
    assert all(0.0 <= v <= 100.0 for v in result.per_object.values())
    # Every object has the same number of test views, so the total is their mean.
    assert result.accuracy == pytest.approx(sum(result.per_object.values()) / len(OBJECTS))
    assert result.n_test == len(OBJECTS) * n_test_angles == 15
    assert result.n_train_views == expected_train_views(exp)
    assert result.recognizer.n_gallery == result.n_train_views
    assert set(result.recognizer.labels.tolist()) == set(OBJECTS)
    assert math.isnan(result.pose_mae_deg) or 0.0 <= result.pose_mae_deg <= 180.0
    assert set(result.seconds) == SECONDS_KEYS
    assert all(v >= 0.0 for v in result.seconds.values())
    if exp.method == "nvs":
        assert set(result.elevations) == set(OBJECTS)
        # One record per seed pair, the elevation fixed.
        assert all(e == [0.0] * (exp.views - 1) for e in result.elevations.values())
    else:
        assert result.seconds["correspondence"] == result.seconds["synthesis"] == 0.0
        assert result.elevations == {}


def test_expected_view_counts() -> None:
    """The counts the record test relies on, spelled out."""
    names = ("nvs", "nvs3", "sparse", "sparse3", "dense")
    assert [expected_train_views(CONFIGS[n]) for n in names] == [12, 18, 6, 9, 15]


@pytest.mark.parametrize(
    ("kwargs", "want"),
    [
        (dict(alpha=15.0), (-20.0, 20.0)),  # two seeds: synth as given
        (dict(alpha=15.0, views=3), (-20.0, 35.0)),  # seeds 0, 15, 30: 20 before, 5 past
        (dict(alpha=5.0, views=3), (-20.0, 25.0)),
        (dict(alpha=-10.0, views=3), (-30.0, 20.0)),  # seeds 0, -10, -20: the start moves
        (dict(alpha=15.0, views=3, synth_follows_seeds=False), (-20.0, 20.0)),
        (dict(alpha=10.0, views=3, synth=(-5.0, 10.0, 5.0)), (-5.0, 20.0)),
    ],
    ids=["two-seeds", "three-seeds-15", "three-seeds-5", "negative-alpha", "fixed", "short"],
)
def test_synth_range_follows_the_seeds(kwargs: dict[str, object], want: tuple[float, float]) -> None:
    exp = CoilExperiment(**kwargs)  # type: ignore[arg-type]
    assert exp.synth_range() == want
    angles = exp.synth_angles()
    assert (angles[0], angles[-1]) == want
    assert angles == angle_range(*want, exp.synth[2], "synth")
    assert exp.synth_angles(5.0) == angle_range(*want, 5.0, "synth")
    # The margins beyond the first and the last seed are those synth gives two seeds.
    seeds = [n * exp.alpha for n in range(exp.views)]
    if exp.synth_follows_seeds and exp.alpha > 0:
        assert (min(seeds) - want[0], want[1] - max(seeds)) == (-exp.synth[0], exp.synth[1] - exp.alpha)


@pytest.mark.coil
def test_three_seeds_gallery_covers_the_seeds(results: dict[str, CoilResult], folder: CoilFolder) -> None:
    """The third seed (20 degrees) lies inside the gallery, and its real view is recognized
    at its pose: it is reproduced there, not just neighboured."""
    rec = results["nvs3"].recognizer
    assert sorted(set(rec.poses.tolist())) == [-5.0, 0.0, 5.0, 10.0, 15.0, 20.0]
    for obj in OBJECTS:
        pred = rec.predict(folder.images(obj, [2 * ALPHA]))
        assert pred.labels.tolist() == [obj]
        assert pred.poses.tolist() == [2 * ALPHA]


@pytest.mark.coil
@pytest.mark.parametrize("name", list(CONFIGS))
def test_to_json(results: dict[str, CoilResult], name: str) -> None:
    record = results[name].to_json()
    assert set(record) == JSON_KEYS
    assert set(record["seconds"]) == SECONDS_KEYS  # type: ignore[arg-type]
    assert record["per_object"] == {str(k): v for k, v in results[name].per_object.items()}
    text = json.dumps(record)
    assert json.loads(text) == record


@pytest.mark.coil
def test_seed_views_are_recognized_with_nvs(results: dict[str, CoilResult], folder: CoilFolder) -> None:
    rec = results["nvs"].recognizer
    seed_poses = [0.0, ALPHA]
    for obj in OBJECTS:
        pred = rec.predict(folder.images(obj, seed_poses))
        assert pred.labels.tolist() == [obj, obj]
        # The nearest gallery view is a synthesized one within one synth step.
        assert (pred.poses - torch.tensor(seed_poses)).abs().max() <= 5.0


@pytest.mark.coil
def test_center_wraps_around_zero(folder: CoilFolder) -> None:
    exp = CoilExperiment(alpha=ALPHA, center=350.0, test=TEST, components=2, method="sparse", objects=[1, 2])
    result = exp.run(folder)
    poses = result.recognizer.poses
    assert sorted(set(poses.tolist())) == [-10.0, 0.0]  # 350 and 360 degrees, wrapped
    assert result.n_test == 10 and 0.0 <= result.accuracy <= 100.0
    assert math.isnan(result.pose_mae_deg) or result.pose_mae_deg <= 180.0


# --------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(method="knn"), r"method must be one of \('nvs', 'sparse', 'dense'\), got 'knn'"),
        (dict(views=4), "views must be 2 or 3, got 4"),
        (dict(views=1), "views must be 2 or 3, got 1"),
        (dict(synth=(-5.0, 10.0, -5.0)), "synth step must be positive, got -5.0"),
        (dict(synth=(10.0, -5.0, 5.0)), "synth must have start <= stop"),
        (dict(test=(10.0, -10.0)), "test must have start <= stop"),
    ],
    ids=["method", "views-4", "views-1", "synth-negative-step", "synth-reversed", "test-reversed"],
)
def test_config_errors(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        CoilExperiment(**kwargs)  # type: ignore[arg-type]


@pytest.mark.coil
@pytest.mark.parametrize(
    ("objects", "match"),
    [([1, 99], r"objects \[99\] are not in"), ([], "objects must name at least one object")],
    ids=["unknown", "empty"],
)
def test_objects_errors(folder: CoilFolder, objects: list[int], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        CoilExperiment(method="sparse", objects=objects).run(folder)


def test_synth_follows_seeds_must_be_bool() -> None:
    with pytest.raises(TypeError, match="synth_follows_seeds must be a bool, got 'no'"):
        CoilExperiment(synth_follows_seeds="no")  # type: ignore[arg-type]


def test_components_validated_at_construction() -> None:
    with pytest.raises(ValueError, match="components"):
        CoilExperiment(components=0)


@pytest.mark.coil
def test_alpha_zero_is_rejected(folder: CoilFolder) -> None:
    with pytest.raises(ValueError, match="alpha"):
        CoilExperiment(alpha=0.0, method="sparse", components=1, objects=[1, 2], test=TEST).run(folder)


def test_rgb_coil100_layout(folder: CoilFolder, tmp_path) -> None:
    """A COIL-100-style folder (pose in degrees, RGB): all three channels go into the views."""
    from skimage.io import imsave
    from skimage.transform import resize

    angles = [350, 355, 0, 5, 10]
    for obj in (1, 2):
        for deg in angles:
            gray = folder.image(obj, deg)[0].numpy()
            small = resize(gray, (32, 32), anti_aliasing=True)
            rgb = (torch.tensor(small)[..., None] * torch.tensor([1.0, 0.7, 0.4])).numpy()
            imsave(
                tmp_path / f"obj{obj}__{deg}.png", (rgb * 255).round().astype("uint8"), check_contrast=False
            )
    rgb_folder = CoilFolder(tmp_path)
    assert rgb_folder.pose_unit == "degrees" and rgb_folder.image_shape == (3, 32, 32)
    exp = CoilExperiment(alpha=5.0, synth=(-5.0, 10.0, 5.0), test=TEST, components=3)
    result = exp.run(rgb_folder)
    assert result.recognizer.projection.in_features == 3 * 32 * 32
    assert result.n_test == 2 * 5 and result.n_train_views == 2 * 4
    assert 0.0 <= result.accuracy <= 100.0
