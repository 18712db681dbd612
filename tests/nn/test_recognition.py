"""Tests for ``NearestNeighborRecognizer``: a brute-force reference, module invariants, errors."""

from __future__ import annotations

import copy
import io

import pytest
import torch

from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer, Recognition, pose_neighbours

IMAGE_SHAPE = (1, 4, 6)
N_FEATURES = 24
K = 5
N_GALLERY = 40
TOL = {torch.float32: dict(atol=1e-5, rtol=1e-5), torch.float64: dict(atol=1e-10, rtol=1e-10)}
DTYPES = pytest.mark.parametrize("dtype", [torch.float32, torch.float64], ids=["float32", "float64"])
DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def randn(*shape: int, seed: int, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """Normal data made on the CPU in float64 with a fixed seed, then cast."""
    gen = torch.Generator().manual_seed(seed)
    return torch.randn(*shape, generator=gen, dtype=torch.float64).to(dtype)


def make_projection(
    dtype: torch.dtype = torch.float64, *, unit_norm: bool = False, seed: int = 0
) -> EigenProjection:
    """A projection onto K random orthonormal directions of the N_FEATURES-dim view space."""
    q, _ = torch.linalg.qr(randn(N_FEATURES, K, seed=seed))
    mean = randn(N_FEATURES, seed=seed + 1)
    eigenvalues = torch.linspace(5.0, 1.0, K, dtype=torch.float64)
    return EigenProjection.from_tensors(
        mean.to(dtype),
        q.T.contiguous().to(dtype),
        eigenvalues.to(dtype),
        IMAGE_SHAPE,
        unit_norm=unit_norm,
    )


def make_recognizer(
    dtype: torch.dtype = torch.float64, *, unit_norm: bool = False, seed: int = 0
) -> NearestNeighborRecognizer:
    """Random codes (G, K), labels in 0..3 (all present) and poses."""
    codes = randn(N_GALLERY, K, seed=seed + 2, dtype=dtype)
    labels = torch.arange(N_GALLERY) % 4
    poses = torch.arange(N_GALLERY, dtype=dtype) * 5.0 - 90.0
    projection = make_projection(dtype, unit_norm=unit_norm, seed=seed)
    return NearestNeighborRecognizer(projection, codes, labels, poses)


def brute_force(
    rec: NearestNeighborRecognizer, x: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The reference: every pairwise distance (no |a|² - 2ab + |b|² expansion), then argmin."""
    z = rec.projection(x)
    d = torch.cdist(z, rec.codes, compute_mode="donot_use_mm_for_euclid_dist")
    best, index = d.min(dim=1)
    return rec.labels[index], rec.poses[index], best, index


@DTYPES
@pytest.mark.parametrize("device", DEVICES)
def test_matches_brute_force(dtype: torch.dtype, device: str) -> None:
    rec = make_recognizer(dtype).to(device)
    x = randn(30, *IMAGE_SHAPE, seed=10, dtype=dtype).to(device)
    labels, poses, distances, index = brute_force(rec, x)

    out = rec(x)
    assert isinstance(out, tuple) and len(out) == 3
    for t in out:
        assert t.shape == (30,) and t.device == x.device
    assert out[0].dtype == torch.int64 and out[1].dtype == dtype and out[2].dtype == dtype
    torch.testing.assert_close(out[0], labels, atol=0, rtol=0)
    torch.testing.assert_close(out[1], poses, atol=0, rtol=0)
    torch.testing.assert_close(out[2], distances, **TOL[dtype])

    pred = rec.predict(x)
    assert isinstance(pred, Recognition)
    torch.testing.assert_close(pred.indices, index, atol=0, rtol=0)
    torch.testing.assert_close(pred.labels, labels, atol=0, rtol=0)
    torch.testing.assert_close(pred.poses, poses, atol=0, rtol=0)
    torch.testing.assert_close(pred.distances, distances, **TOL[dtype])


@DTYPES
def test_flat_and_image_inputs_agree(dtype: torch.dtype) -> None:
    rec = make_recognizer(dtype)
    x = randn(8, *IMAGE_SHAPE, seed=11, dtype=dtype)
    for a, b in zip(rec(x), rec(x.flatten(1)), strict=True):
        torch.testing.assert_close(a, b, atol=0, rtol=0)


@DTYPES
def test_exact_gallery_views_are_found(dtype: torch.dtype) -> None:
    projection = make_projection(dtype)
    views = 10 * randn(12, *IMAGE_SHAPE, seed=12, dtype=dtype)
    labels = torch.tensor([3, 7, 9] * 4)
    poses = torch.arange(12, dtype=dtype) * 5.0
    rec = NearestNeighborRecognizer.from_views(projection, views, labels, poses, label_names=["a", "b", "c"])
    pred = rec.predict(views)
    torch.testing.assert_close(pred.indices, torch.arange(12), atol=0, rtol=0)
    torch.testing.assert_close(pred.labels, labels, atol=0, rtol=0)
    torch.testing.assert_close(pred.poses, poses, atol=0, rtol=0)
    # |z|² - 2 z·g + |g|² cancels down to rounding noise of order eps·|z|²; the distance is
    # its square root, so "zero" means below a few sqrt(eps)·|z|, not below eps.
    scale = float(rec.codes.norm(dim=1).max())
    assert float(pred.distances.max()) <= 8 * torch.finfo(dtype).eps ** 0.5 * scale
    assert rec.label_names == ["a", "b", "c"]


@DTYPES
def test_unit_norm_ignores_brightness(dtype: torch.dtype) -> None:
    projection = make_projection(dtype, unit_norm=True)
    gallery = randn(20, *IMAGE_SHAPE, seed=13, dtype=dtype)
    rec = NearestNeighborRecognizer.from_views(
        projection, gallery, torch.arange(20) % 5, torch.arange(20, dtype=dtype)
    )
    x = randn(9, *IMAGE_SHAPE, seed=14, dtype=dtype)
    bright, plain = rec.predict(3 * x), rec.predict(x)
    torch.testing.assert_close(bright.indices, plain.indices, atol=0, rtol=0)
    torch.testing.assert_close(bright.labels, plain.labels, atol=0, rtol=0)
    torch.testing.assert_close(bright.poses, plain.poses, atol=0, rtol=0)
    torch.testing.assert_close(bright.distances, plain.distances, **TOL[dtype])
    # And a scaled gallery view is still that view.
    again = rec.predict(3 * gallery)
    torch.testing.assert_close(again.indices, torch.arange(20), atol=0, rtol=0)


def test_state_dict_round_trip_into_fresh_recognizer() -> None:
    rec = make_recognizer(torch.float64, unit_norm=True, seed=0)
    fresh = make_recognizer(torch.float64, unit_norm=False, seed=100)
    x = randn(10, *IMAGE_SHAPE, seed=15)
    assert not torch.equal(fresh(x)[2], rec(x)[2])

    buffer = io.BytesIO()
    torch.save(rec.state_dict(), buffer)
    buffer.seek(0)
    fresh.load_state_dict(torch.load(buffer, weights_only=True))

    assert fresh.projection.unit_norm is True  # extra state of the projection
    assert fresh.projection.image_shape == IMAGE_SHAPE
    for a, b in zip(fresh(x), rec(x), strict=True):
        torch.testing.assert_close(a, b, atol=0, rtol=0)
    assert set(rec.state_dict()) >= {"codes", "codes_sqnorm", "labels", "poses", "projection.mean"}
    assert not list(rec.parameters())  # frozen state lives in buffers


def test_module_invariants() -> None:
    rec = make_recognizer(torch.float64)
    x = randn(7, *IMAGE_SHAPE, seed=16)
    before = x.clone()
    out = rec(x)
    torch.testing.assert_close(x, before, atol=0, rtol=0)  # input not modified in place
    per_sample = [rec(x[i : i + 1]) for i in range(7)]
    for j in range(3):
        torch.testing.assert_close(out[j], torch.cat([p[j] for p in per_sample]))

    buffer = io.BytesIO()
    torch.save(rec, buffer)
    buffer.seek(0)
    unpickled = torch.load(buffer, weights_only=False)
    assert repr(unpickled) == repr(rec)
    for a, b in zip(unpickled(x), out, strict=True):
        torch.testing.assert_close(a, b, atol=0, rtol=0)

    as_float = copy.deepcopy(rec).float()
    assert as_float.codes.dtype == torch.float32 and as_float.labels.dtype == torch.int64
    torch.testing.assert_close(as_float(x.float())[0], out[0], atol=0, rtol=0)
    assert f"gallery={N_GALLERY}, labels=4" in repr(rec)


@pytest.mark.parametrize("shape", [(0, *IMAGE_SHAPE), (0, N_FEATURES)], ids=["images", "flat"])
def test_empty_batch(shape: tuple[int, ...]) -> None:
    rec = make_recognizer(torch.float64)
    labels, poses, distances = rec(torch.zeros(shape, dtype=torch.float64))
    assert labels.shape == poses.shape == distances.shape == (0,)
    assert labels.dtype == torch.int64 and poses.dtype == torch.float64
    assert rec.predict(torch.zeros(shape, dtype=torch.float64)).indices.shape == (0,)


def _args() -> dict[str, object]:
    return dict(
        projection=make_projection(),
        codes=randn(4, K, seed=17),
        labels=torch.tensor([0, 0, 1, 2]),
        poses=torch.tensor([0.0, 5.0, 10.0, 15.0], dtype=torch.float64),
    )


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        (dict(codes=randn(4, K + 1, seed=1)), ValueError, r"codes must have shape \(G, 5\)"),
        (dict(codes=randn(4, K, 1, seed=1)), ValueError, r"codes must have shape \(G, k\)"),
        (dict(codes=torch.zeros(0, K, dtype=torch.float64)), ValueError, "at least one gallery view"),
        (dict(codes=torch.zeros(4, K, dtype=torch.int64)), TypeError, "codes must have a floating dtype"),
        (dict(codes=torch.full((4, K), float("nan"))), ValueError, "codes must be finite"),
        (dict(labels=torch.tensor([0.0, 0.0, 1.0, 2.0])), ValueError, "labels must be an integer tensor"),
        (
            dict(labels=torch.tensor([0, 1, 2])),
            ValueError,
            r"labels must be an integer tensor of shape \(4,\)",
        ),
        (dict(poses=torch.zeros(3)), ValueError, r"poses must have shape \(4,\), got \(3,\)"),
        (dict(label_names=["a", "b"]), ValueError, "label_names must name the 3 distinct labels, got 2"),
        (dict(projection=torch.nn.Linear(N_FEATURES, K)), TypeError, "projection must be an EigenProjection"),
    ],
    ids=[
        "codes-wrong-k",
        "codes-3d",
        "codes-empty",
        "codes-int",
        "codes-nan",
        "labels-float",
        "labels-length",
        "poses-length",
        "label-names-count",
        "not-eigenprojection",
    ],
)
def test_constructor_errors(change: dict[str, object], error: type[Exception], match: str) -> None:
    args = _args()
    args.update(change)
    with pytest.raises(error, match=match):
        NearestNeighborRecognizer(**args)  # type: ignore[arg-type]


def test_input_errors() -> None:
    rec = make_recognizer(torch.float64)
    with pytest.raises(TypeError, match="x must have a floating dtype"):
        rec(torch.zeros(2, *IMAGE_SHAPE, dtype=torch.int64))
    with pytest.raises(TypeError, match="x must have a floating dtype"):
        rec.predict(torch.zeros(2, *IMAGE_SHAPE, dtype=torch.int64))
    # Any floating dtype is cast to the recognizer's, by forward and predict alike.
    x = randn(3, *IMAGE_SHAPE, seed=5, dtype=torch.float64)
    expected = rec.predict(x)
    for cast in (torch.float32, torch.bfloat16):
        got = rec.predict(x.to(cast))
        assert got.distances.dtype == torch.float64
        torch.testing.assert_close(rec(x.to(cast))[0], got.labels)
    torch.testing.assert_close(rec.predict(x.float()).labels, expected.labels)
    with pytest.raises(ValueError, match="x must have shape"):
        rec(torch.zeros(2, 5, dtype=torch.float64))


def test_labels_as_list_raise_type_error() -> None:
    args = _args()
    args["labels"] = [0, 0, 1, 2]
    with pytest.raises(TypeError, match="labels"):
        NearestNeighborRecognizer(**args)  # type: ignore[arg-type]


def test_nan_pose_is_rejected() -> None:
    args = _args()
    args["poses"] = torch.tensor([0.0, float("nan"), 10.0, 15.0], dtype=torch.float64)
    with pytest.raises(ValueError, match="poses must be finite"):
        NearestNeighborRecognizer(**args)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- pose interpolation
def circle_recognizer(
    step: float, stop: float, dtype: torch.dtype = torch.float64
) -> NearestNeighborRecognizer:
    """One object whose codes trace the unit circle (cos θ, sin θ) at poses 0, step, … < stop."""
    poses = torch.arange(0.0, stop, step, dtype=torch.float64)
    codes = torch.stack([torch.cos(torch.deg2rad(poses)), torch.sin(torch.deg2rad(poses))], dim=1)
    projection = EigenProjection.from_tensors(torch.zeros(2, dtype=dtype), torch.eye(2, dtype=dtype))
    return NearestNeighborRecognizer(
        projection, codes.to(dtype), torch.zeros(len(poses), dtype=torch.long), poses.to(dtype)
    )


def on_circle(degrees: list[float]) -> torch.Tensor:
    rad = torch.deg2rad(torch.tensor(degrees, dtype=torch.float64))
    return torch.stack([torch.cos(rad), torch.sin(rad)], dim=1)


@DTYPES
def test_interpolated_pose_between_gallery_views(dtype: torch.dtype) -> None:
    """On a closed manifold the pose lands between the gallery views, both ways round."""
    rec = circle_recognizer(10.0, 360.0, dtype)
    truth = [23.0, 27.0, 2.0, 357.0, 181.0]
    x = on_circle(truth).to(dtype)
    nearest = rec.predict(x)
    assert nearest.poses.tolist() == [20.0, 30.0, 0.0, 0.0, 180.0]
    refined = rec.predict(x, interpolate_pose=True).poses
    err = torch.remainder(refined.double() - torch.tensor(truth, dtype=torch.float64) + 180, 360) - 180
    # A chord of a 10-degree arc: the fraction along it is within 0.05 degrees of the angle's.
    assert float(err.abs().max()) < 0.05
    assert refined.dtype == dtype
    torch.testing.assert_close(rec.predict(x, interpolate_pose=True).labels, nearest.labels)


def test_interpolated_pose_keeps_gallery_poses_and_open_ends() -> None:
    """A gallery view's own code keeps its pose; an open arc does not wrap round."""
    rec = circle_recognizer(10.0, 100.0)  # 0..90: open, 270 degrees from 90 round to 0
    assert rec.pose_before.tolist()[0] == 0 and rec.pose_after.tolist()[-1] == 9
    refined = rec.predict(rec.codes, interpolate_pose=True).poses
    torch.testing.assert_close(refined, rec.poses, atol=1e-9, rtol=0)
    beyond = rec.predict(on_circle([-5.0, 95.0]), interpolate_pose=True).poses
    assert beyond.tolist() == [0.0, 90.0]  # clamped to the arc's ends


def test_pose_neighbours_per_label_and_loop_rule() -> None:
    labels = torch.tensor([1, 0, 1, 0, 1, 0])
    poses = torch.tensor([180.0, 0.0, 0.0, 350.0, 90.0, 10.0])
    before, after = pose_neighbours(labels, poses)
    # Label 0 at 0, 10, 350: gaps 10 and 340; round from 350 to 0 is 10 <= 1.5 * 340: a loop.
    assert (before[1], after[1]) == (3, 5) and (before[3], after[3]) == (5, 1)
    # Label 1 at 0, 90, 180: round from 180 to 0 is 180 > 1.5 * 90: open ends.
    assert (before[2], after[2]) == (2, 4) and (before[0], after[0]) == (4, 0)


def test_interpolate_pose_must_be_bool() -> None:
    rec = circle_recognizer(10.0, 360.0)
    with pytest.raises(TypeError, match="interpolate_pose must be a bool, got str"):
        rec.predict(on_circle([1.0]), interpolate_pose="yes")  # type: ignore[arg-type]


# --- predict-side checks (forward stays export-friendly) ------------------------------


def _small_recognizer(unit_norm: bool = False) -> NearestNeighborRecognizer:
    x = randn(6, N_FEATURES, seed=3, dtype=torch.float32)
    proj = make_projection(torch.float32, unit_norm=unit_norm)
    return NearestNeighborRecognizer.from_views(proj, x, torch.arange(6) % 2, torch.arange(6.0))


def test_predict_refuses_non_finite_views() -> None:
    rec = _small_recognizer()
    x = randn(2, N_FEATURES, seed=4, dtype=torch.float32)
    x[1, 3] = float("nan")
    with pytest.raises(ValueError, match=r"x must be finite, got 1 NaN"):
        rec.predict(x)
    labels, _, distances = rec(x)  # the module itself does not check: NaN out, no error
    assert not bool(torch.isfinite(distances).all()) and labels.shape == (2,)
    assert rec.predict(x[:0]).distances.shape == (0,)


def test_predict_unit_norm_any_scale() -> None:
    """Views whose L2 norm overflows float32 (1e30 x 1e8 squares) are scaled before the norm:
    the same answers as the views themselves, not an error and not zeros (issue 41, class 3)."""
    rec = _small_recognizer(unit_norm=True)
    x = randn(2, N_FEATURES, seed=4, dtype=torch.float32)
    ref = rec.predict(x)
    for scale in (1e-30, 1e30, 3e37):
        got = rec.predict(x * scale)
        assert torch.equal(got.labels, ref.labels)
        torch.testing.assert_close(got.distances, ref.distances, rtol=1e-5, atol=1e-6)


def test_predict_damaged_gallery() -> None:
    rec = _small_recognizer()
    rec.codes[0, 0] = float("inf")
    with pytest.raises(ValueError, match="gallery codes are not finite"):
        rec.predict(randn(2, N_FEATURES, seed=4, dtype=torch.float32))


@pytest.mark.parametrize("names", ["ab", {0: "a", 1: "b"}, 7], ids=["str", "dict", "int"])
def test_label_names_must_be_a_list(names: object) -> None:
    x = randn(2, N_FEATURES, seed=4)
    with pytest.raises(TypeError, match="label_names must be None or a list of names"):
        NearestNeighborRecognizer.from_views(
            make_projection(), x, torch.tensor([0, 1]), torch.zeros(2), names
        )  # type: ignore[arg-type]
