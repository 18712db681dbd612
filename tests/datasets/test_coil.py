"""Tests for torch_eigview.datasets.coil: the COIL folder loader and the object-spec parser."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import skimage.io
import torch

from torch_eigview.datasets.background import BackgroundModel
from torch_eigview.datasets.coil import CoilFolder, PoseStepWarning, parse_object_spec
from torch_eigview.evaluation.circle import grid_step
from torch_eigview.io import images

COIL20 = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "coil-20-proc"
needs_coil20 = pytest.mark.skipif(
    not COIL20.is_dir(), reason=f"COIL-20 images not found at {COIL20} (../shared/data/coil-20-proc)"
)


def _write(folder: Path, name: str, img: np.ndarray) -> Path:
    path = folder / name
    skimage.io.imsave(path, img, check_contrast=False)
    return path


def _rgb_folder(tmp_path: Path, channels: int = 3) -> dict[tuple[int, int], np.ndarray]:
    """A COIL-100-style folder: P in degrees, 8×8 uint8 images with `channels` channels."""
    rng = np.random.default_rng(0)
    written = {}
    for obj in (1, 2):
        for deg in (0, 5, 90, 355):
            img = rng.integers(0, 256, size=(8, 8, channels), dtype=np.uint8)
            _write(tmp_path, f"obj{obj}__{deg}.png", img)
            written[obj, deg] = img
    (tmp_path / "readme.txt").write_text("not an image")
    (tmp_path / "obj1__5.jpg").write_bytes(b"ignored: wrong extension")
    return written


# --- real COIL-20 ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def coil20() -> CoilFolder:
    return CoilFolder(COIL20)


@needs_coil20
@pytest.mark.coil
def test_coil20_layout(coil20: CoilFolder) -> None:
    assert coil20.objects == list(range(1, 21))
    assert coil20.pose_unit == "index"
    assert coil20.image_shape == (1, 128, 128)
    assert len(coil20) == 1440
    assert coil20.poses(3) == [5.0 * p for p in range(72)]
    text = repr(coil20)
    for part in ("objects=20", "files=1440", "pose_unit='index'", "(1, 128, 128)"):
        assert part in text


@needs_coil20
@pytest.mark.coil
def test_coil20_image_matches_file(coil20: CoilFolder) -> None:
    ref = torch.from_numpy(skimage.io.imread(COIL20 / "obj1__63.png")).float()[None] / 255
    a, b = coil20.image(1, -45), coil20.image(1, 315)
    assert a.shape == (1, 128, 128) and a.dtype == torch.float32
    assert torch.equal(a, ref) and torch.equal(b, ref)
    assert 0.0 <= float(a.min()) and float(a.max()) <= 1.0
    assert torch.equal(coil20.image(1, 315 + 360 + 1e-9), ref)


@needs_coil20
@pytest.mark.coil
def test_images_arrive_on_the_folder_device(coil20: CoilFolder) -> None:
    """The device argument places every returned view (the meta device stands in for CUDA)."""
    meta = CoilFolder(COIL20, device="meta")
    views = meta.images(1, [0.0, 5.0])
    assert views.device.type == "meta" and views.shape == (2, 1, 128, 128)
    assert coil20.images(1, [0.0]).device.type == "cpu"


@needs_coil20
@pytest.mark.coil
def test_coil20_images_and_load_all(coil20: CoilFolder) -> None:
    stack = coil20.images(2, [0, 5, 350])
    assert stack.shape == (3, 1, 128, 128)
    for t, deg in enumerate((0, 5, 350)):
        assert torch.equal(stack[t], coil20.image(2, deg))
    assert torch.equal(coil20.images(2, torch.tensor([10.0]))[0], coil20.image(2, 10))
    imgs, labels, poses = coil20.load_all([4, 2])
    assert imgs.shape == (144, 1, 128, 128)
    assert labels.dtype == torch.int64 and labels[:72].eq(4).all() and labels[72:].eq(2).all()
    assert poses.dtype == torch.float64 and poses[:72].tolist() == [5.0 * p for p in range(72)]
    assert torch.equal(imgs[73], coil20.image(2, 5))


@needs_coil20
@pytest.mark.coil
def test_coil20_float64_and_explicit_unit() -> None:
    folder = CoilFolder(str(COIL20), pose_unit="index", dtype=torch.float64)
    img = folder.image(5, 90)
    ref = torch.from_numpy(skimage.io.imread(COIL20 / "obj5__18.png")).double()[None] / 255
    assert img.dtype == torch.float64 and torch.equal(img, ref)


@needs_coil20
@pytest.mark.coil
def test_coil20_missing_angle_lists_briefly(coil20: CoilFolder) -> None:
    with pytest.raises(
        ValueError, match=r"degrees=2\.5 .*available: \[0, 5, 10, \.\.\., 350, 355\] \(72 poses\)"
    ):
        coil20.image(1, 2.5)


# --- synthetic folders ----------------------------------------------------------------


def test_rgb_degrees_folder(tmp_path: Path) -> None:
    written = _rgb_folder(tmp_path)
    folder = CoilFolder(tmp_path)
    assert folder.pose_unit == "degrees"
    assert folder.objects == [1, 2] and len(folder) == 8
    assert folder.image_shape == (3, 8, 8)
    assert folder.poses(1) == [0.0, 5.0, 90.0, 355.0]
    for (obj, deg), img in written.items():
        expected = torch.from_numpy(img).permute(2, 0, 1).float() / 255
        assert torch.equal(folder.image(obj, deg), expected)
    assert torch.equal(folder.image(2, -5), folder.image(2, 355))
    assert folder.images(1, [0, 90]).shape == (2, 3, 8, 8)


def test_returned_tensor_does_not_alias_cache(tmp_path: Path) -> None:
    _rgb_folder(tmp_path)
    folder = CoilFolder(tmp_path)
    first = folder.image(1, 0)
    first.fill_(-1.0)
    assert float(folder.image(1, 0).min()) >= 0.0


def test_rgba_drops_alpha(tmp_path: Path) -> None:
    written = _rgb_folder(tmp_path, channels=4)
    folder = CoilFolder(tmp_path)
    assert folder.image_shape == (3, 8, 8)
    expected = torch.from_numpy(written[2, 90][..., :3]).permute(2, 0, 1).float() / 255
    assert torch.equal(folder.image(2, 90), expected)


def test_uint16_grayscale_scaled(tmp_path: Path) -> None:
    img = np.array([[0, 1000], [65535, 7]], dtype=np.uint16)
    _write(tmp_path, "obj3__0.png", img)
    folder = CoilFolder(tmp_path, dtype=torch.float16)
    assert folder.pose_unit == "index"
    out = folder.image(3, 0)
    assert out.dtype == torch.float16 and out.shape == (1, 2, 2)
    torch.testing.assert_close(out[0], torch.from_numpy(img.astype(np.float32) / 65535).half())


def test_auto_unit_index_when_all_poses_small(tmp_path: Path) -> None:
    img = np.zeros((4, 4), dtype=np.uint8)
    for p in (0, 1, 71):
        _write(tmp_path, f"obj1__{p}.png", img)
    folder = CoilFolder(tmp_path)
    assert folder.pose_unit == "index"
    assert folder.poses(1) == [0.0, 5.0, 355.0]
    assert CoilFolder(tmp_path, pose_unit="degrees").poses(1) == [0.0, 1.0, 71.0]


def test_no_coil_files(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("x")
    (tmp_path / "obj1_0.png").write_bytes(b"")
    (tmp_path / "obj1__0.PNG").write_bytes(b"")
    with pytest.raises(ValueError, match=r"holds no COIL files \(obj\{O\}__\{P\}\.png\)"):
        CoilFolder(tmp_path)


def test_bad_root_and_arguments(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="must be an existing directory"):
        CoilFolder(tmp_path / "missing")
    file = tmp_path / "file.txt"
    file.write_text("x")
    with pytest.raises(ValueError, match="must be an existing directory"):
        CoilFolder(file)
    with pytest.raises(TypeError, match="root must be"):
        CoilFolder(3)  # type: ignore[arg-type]
    _rgb_folder(tmp_path)
    with pytest.raises(
        ValueError, match=r"pose_unit='radians' must be one of \('auto', 'index', 'degrees'\)"
    ):
        CoilFolder(tmp_path, pose_unit="radians")
    with pytest.raises(TypeError, match="dtype must be a floating"):
        CoilFolder(tmp_path, dtype=torch.int64)


def test_pose_out_of_range_for_unit(tmp_path: Path) -> None:
    img = np.zeros((4, 4), dtype=np.uint8)
    _write(tmp_path, "obj1__0.png", img)
    _write(tmp_path, "obj1__72.png", img)
    with pytest.raises(
        ValueError, match=r"pose_unit='index' with 5 degrees a pose needs P in 0\.\.71.*obj1__72\.png"
    ):
        CoilFolder(tmp_path, pose_unit="index")
    _write(tmp_path, "obj1__360.png", img)
    with pytest.raises(ValueError, match=r"needs P in 0\.\.359.*obj1__360\.png"):
        CoilFolder(tmp_path)


def test_duplicate_view(tmp_path: Path) -> None:
    img = np.zeros((4, 4), dtype=np.uint8)
    _write(tmp_path, "obj1__5.png", img)
    _write(tmp_path, "obj1__05.png", img)
    with pytest.raises(ValueError, match="name the same view"):
        CoilFolder(tmp_path)


# imageio falls back through every plugin on a junk file, importing its deprecated DICOM one.
@pytest.mark.filterwarnings("ignore:The legacy `DICOM` plugin:DeprecationWarning")
def test_corrupt_png(tmp_path: Path) -> None:
    _rgb_folder(tmp_path)
    bad = tmp_path / "obj2__15.png"
    bad.write_bytes(b"this is not a png")
    folder = CoilFolder(tmp_path)  # the first file (obj1__0.png) is fine
    with pytest.raises(ValueError, match=re.escape(str(bad))):
        folder.image(2, 15)
    only_bad = tmp_path / "corrupt"
    only_bad.mkdir()
    (only_bad / "obj7__0.png").write_bytes(b"junk")
    with pytest.raises(ValueError, match=r"obj7__0\.png is not an image file that can be read"):
        CoilFolder(only_bad)


def test_mixed_sizes(tmp_path: Path) -> None:
    _write(tmp_path, "obj1__0.png", np.zeros((8, 8), dtype=np.uint8))
    _write(tmp_path, "obj1__1.png", np.zeros((6, 8), dtype=np.uint8))
    _write(tmp_path, "obj1__2.png", np.zeros((8, 8, 3), dtype=np.uint8))
    folder = CoilFolder(tmp_path)
    with pytest.raises(ValueError, match=r"obj1__1\.png must have shape .*\(1, 8, 8\).*got \(1, 6, 8\)"):
        folder.image(1, 5)
    with pytest.raises(ValueError, match=r"obj1__2\.png must have shape .*got \(3, 8, 8\)"):
        folder.images(1, [0, 10])
    with pytest.raises(ValueError, match=r"obj1__1\.png"):
        folder.load_all()


def test_unknown_object_and_missing_angle(tmp_path: Path) -> None:
    _rgb_folder(tmp_path)
    folder = CoilFolder(tmp_path)
    with pytest.raises(ValueError, match=r"obj=9 is not in .*objects: \[1, 2\]"):
        folder.image(9, 0)
    with pytest.raises(ValueError, match=r"obj=9"):
        folder.poses(9)
    with pytest.raises(
        ValueError, match=r"obj=1 has no image at degrees=45\.0 .*available: \[0, 5, 90, 355\] \(4 poses\)"
    ):
        folder.image(1, 45)
    with pytest.raises(ValueError, match=r"obj=1 has no image at degrees=5\.001"):
        folder.images(1, [0, 5.001])
    with pytest.raises(ValueError, match="degrees=nan must be finite"):
        folder.image(1, float("nan"))
    with pytest.raises(TypeError, match="degrees must be a number"):
        folder.image(1, "0")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="obj must be an int"):
        folder.image(1.0, 0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="objects must name at least one"):
        folder.load_all([])


def test_float_images_kept_and_checked(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # PNG holds no float pixels, so stand in for the decoder to reach the float branch.
    _write(tmp_path, "obj1__0.png", np.zeros((4, 4), dtype=np.uint8))
    _write(tmp_path, "obj1__1.png", np.zeros((4, 4), dtype=np.uint8))
    pixels = {"obj1__0.png": np.full((4, 4), 0.25), "obj1__1.png": np.full((4, 4), np.nan)}
    monkeypatch.setattr(images, "_decode", lambda path: (pixels[Path(path).name], 1))
    folder = CoilFolder(tmp_path)
    assert torch.equal(folder.image(1, 0), torch.full((1, 4, 4), 0.25))
    with pytest.raises(ValueError, match=r"obj1__1\.png must be finite"):
        folder.image(1, 5)


# --- parse_object_spec ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("4", [4]),
        ("1-20", list(range(1, 21))),
        ("1,3,5-7", [1, 3, 5, 6, 7]),
        ("7,5-7, 1", [1, 5, 6, 7]),
        ("3-3", [3]),
        (" 2 - 4 ", [2, 3, 4]),
    ],
)
def test_parse_object_spec(spec: str, expected: list[int]) -> None:
    assert parse_object_spec(spec) == expected


@pytest.mark.parametrize("spec", ["", "a", "1,", ",2", "1-", "-3", "1-2-3", "1;2", "0", "0-3", "2.5", "7-5"])
def test_parse_object_spec_rejects(spec: str) -> None:
    with pytest.raises(ValueError, match=re.escape(f"spec={spec!r}")):
        parse_object_spec(spec)


def test_parse_object_spec_type() -> None:
    with pytest.raises(TypeError, match="spec must be a string"):
        parse_object_spec(5)  # type: ignore[arg-type]


# --- pose indices of another turntable step ---------------------------------------------


def _index_folder(tmp_path: Path, n: int, objects: tuple[int, ...] = (1, 2)) -> Path:
    img = np.zeros((4, 4), dtype=np.uint8)
    for obj in objects:
        for p in range(n):
            _write(tmp_path, f"obj{obj}__{p}.png", img)
    return tmp_path


def test_a_whole_turntable_of_36_indices_warns_and_takes_its_step(tmp_path: Path) -> None:
    root = _index_folder(tmp_path, 36)
    with pytest.warns(PoseStepWarning, match=r"indices 0\.\.35.*0\.\.175 degrees.*pass pose_step=10 "):
        folder = CoilFolder(root)
    assert folder.poses(1) == [5.0 * i for i in range(36)]  # COIL-20's step, as before
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ten = CoilFolder(root, pose_step=10)
        assert CoilFolder(root, pose_unit="index", pose_step=10).poses(2) == ten.poses(2)
    assert ten.pose_step == 10.0 and ten.poses(1) == [10.0 * i for i in range(36)]
    assert grid_step(ten.poses(1)) == 10.0 and "pose_step=10" in repr(ten)
    assert ten.path(1, 350.0).name == "obj1__35.png" and ten.path(1, -10.0).name == "obj1__35.png"


def test_no_warning_for_coil20_indices_or_other_sets(tmp_path: Path) -> None:
    img = np.zeros((4, 4), dtype=np.uint8)
    for name in "abcd":
        (tmp_path / name).mkdir()
    _index_folder(tmp_path / "a", 72)  # COIL-20
    _index_folder(tmp_path / "b", 36, objects=(1,))
    _index_folder(tmp_path / "b", 30, objects=(2,))  # not the same set for every object
    for p in (0, 2):  # not 0..N-1
        _write(tmp_path / "c", f"obj1__{p}.png", img)
    _index_folder(tmp_path / "d", 2)  # two views: 180 degrees apart round a turntable
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert [CoilFolder(tmp_path / name).pose_step for name in "abcd"] == [5.0] * 4


def test_pose_step_errors(tmp_path: Path) -> None:
    root = _index_folder(tmp_path, 36)
    for bad in (0, -5, 361, float("nan"), float("inf")):
        with pytest.raises(ValueError, match=r"pose_step must be a number of degrees in \(0, 360\]"):
            CoilFolder(root, pose_step=bad)
    with pytest.raises(TypeError, match="pose_step must be a number, got str"):
        CoilFolder(root, pose_step="10")  # type: ignore[arg-type]
    with pytest.raises(
        ValueError, match=r"pose_step=10 is the step between pose indices.*pose_unit='degrees'"
    ):
        CoilFolder(root, pose_unit="degrees", pose_step=10)
    with pytest.raises(ValueError, match=r"with 20 degrees a pose needs P in 0\.\.17.*obj1__18\.png"):
        CoilFolder(root, pose_step=20)
    (tmp_path / "deg").mkdir()
    _rgb_folder(tmp_path / "deg")
    with pytest.raises(
        ValueError, match=r"pose_step=5 needs pose files named by index.*resolved to 'degrees'"
    ):
        CoilFolder(tmp_path / "deg", pose_step=5)


def test_grid_step() -> None:
    assert grid_step([5.0 * i for i in range(72)]) == 5.0
    assert grid_step([350.0, 10.0, 30.0]) == 20.0  # round the circle: 350 -> 10
    assert grid_step([90.0]) == 360.0


# --- a backdrop that is not black -------------------------------------------------------


def _backdrop_folder(tmp_path: Path) -> np.ndarray:
    """Two objects x 4 views: a gray backdrop (110) with a bright square (200) and a darker
    patch inside it (40) at a place that moves with the pose."""
    for obj in (1, 2):
        for p in range(4):
            img = np.full((16, 16), 110, dtype=np.uint8)
            img[4:12, 3 + p : 9 + p] = 200
            img[6:8, 4 + p : 6 + p] = 40
            _write(tmp_path, f"obj{obj}__{p}.png", img)
    return img


@pytest.mark.filterwarnings("ignore::torch_eigview.datasets.coil.PoseStepWarning")  # 4 views named 0..3
def test_background_model_sets_the_backdrop_to_zero(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    last = _backdrop_folder(tmp_path)
    model = BackgroundModel(background=(110 / 255,), tolerance=8 / 255)
    folder = CoilFolder(tmp_path, background=model)
    calls = []
    masks = BackgroundModel.masks
    monkeypatch.setattr(
        BackgroundModel, "masks", lambda self, x, m=None: calls.append(1) or masks(self, x, m)
    )
    view = folder.image(2, 15.0)
    expected = np.where(last == 110, 0, last).astype(np.float32) / 255
    np.testing.assert_array_equal(view[0].numpy(), expected)  # the object's pixels as read, the backdrop 0
    assert torch.equal(folder.images(2, [15.0, 15.0])[1], view) and len(calls) == 1  # one estimate a file
    assert torch.equal(folder.load_all([2])[0][3], view)
    assert "background=BackgroundModel(" in repr(folder)
    raw = CoilFolder(tmp_path).image(2, 15.0)
    assert float(raw[0, 0, 0]) == pytest.approx(110 / 255)


@pytest.mark.filterwarnings("ignore::torch_eigview.datasets.coil.PoseStepWarning")  # 4 views named 0..3
def test_background_errors_name_the_file(tmp_path: Path) -> None:
    _backdrop_folder(tmp_path)
    with pytest.raises(TypeError, match="background must be a BackgroundModel or None, got tuple"):
        CoilFolder(tmp_path, background=(0.4,))  # type: ignore[arg-type]
    _write(tmp_path, "obj1__5.png", np.full((16, 16), 110, dtype=np.uint8))  # no object in view
    folder = CoilFolder(tmp_path, background=BackgroundModel(background=(110 / 255,), tolerance=8 / 255))
    with pytest.raises(ValueError, match=r"obj1__5\.png: .*leaves no object"):
        folder.image(1, 25.0)
