"""View manifests (CSV, folder pattern, COIL) and the ViewDataset over them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import skimage.io
import torch
from torch.utils.data import DataLoader

from torch_eigview.datasets import CoilFolder, ViewDataset, ViewManifest, read_view


def _save(path: Path, arr: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    skimage.io.imsave(path, arr, check_contrast=False)
    return path


def _gray(seed: int, shape: tuple[int, int] = (12, 16), dtype: type = np.uint8) -> np.ndarray:
    top = np.iinfo(dtype).max
    return np.random.default_rng(seed).integers(0, top, size=shape, endpoint=True).astype(dtype)


def _write_csv(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.fixture
def views(tmp_path: Path) -> Path:
    """Two objects, three views each, with masks; a manifest in tmp_path."""
    rows = ["path,object,azimuth,elevation,mask"]
    for o, obj in enumerate(("cup", "box")):
        for k, az in enumerate((20, 0, 350)):
            img = _save(tmp_path / obj / f"{az}.png", _gray(10 * o + k))
            m = np.zeros((12, 16), np.uint8)
            m[3:9, 4 + k : 12] = 255
            _save(tmp_path / obj / f"{az}-mask.png", m)
            rows.append(f"{obj}/{img.name},{obj},{az},10,{obj}/{az}-mask.png")
    return _write_csv(tmp_path / "views.csv", rows)


def test_csv_manifest_reads_paths_angles_and_masks(views: Path) -> None:
    man = ViewManifest.from_csv(views)
    assert man.objects == ["cup", "box"]
    assert len(man) == 6
    cup = man.views("cup")
    assert [v.azimuth for v in cup] == [0.0, 20.0, 350.0]
    assert all(v.elevation == 10.0 for v in cup)
    assert cup[0].path == views.parent / "cup" / "0.png"
    assert cup[0].mask == views.parent / "cup" / "0-mask.png"
    item = ViewDataset(man)[man.entries.index(cup[0])]
    np.testing.assert_array_equal(
        item["image"][0].numpy(), (skimage.io.imread(cup[0].path) / np.float32(255)).astype(np.float32)
    )
    assert item["image"].dtype == torch.float32 and item["mask"].dtype == torch.bool
    assert item["mask"].shape == (1, 12, 16)
    np.testing.assert_array_equal(item["mask"][0].numpy(), skimage.io.imread(cup[0].mask) > 0)
    assert (item["object"], item["azimuth"], item["elevation"]) == ("cup", 0.0, 10.0)


def test_dataset_works_with_a_dataloader(views: Path) -> None:
    ds = ViewDataset(ViewManifest.from_csv(views), size=(8, 10))
    batch = next(iter(DataLoader(ds, batch_size=4, shuffle=False)))
    assert batch["image"].shape == (4, 1, 8, 10) and batch["mask"].shape == (4, 1, 8, 10)
    assert batch["mask"].dtype == torch.bool
    assert batch["object"] == ["cup", "cup", "cup", "box"]
    assert batch["azimuth"].tolist() == [20.0, 0.0, 350.0, 20.0]
    assert float(batch["image"].min()) >= 0.0 and float(batch["image"].max()) <= 1.0


def test_resize_keeps_constant_images_and_mask_area(tmp_path: Path) -> None:
    _save(tmp_path / "a.png", np.full((40, 60, 3), 128, np.uint8))
    m = np.zeros((40, 60), np.uint8)
    m[10:30, 16:46] = 1  # a quarter of the frame
    _save(tmp_path / "a-mask.png", m)
    _write_csv(tmp_path / "m.csv", ["path,object,azimuth,mask", "a.png,a,0,a-mask.png"])
    item = ViewDataset(ViewManifest.from_csv(tmp_path / "m.csv"), size=(20, 30))[0]
    assert item["image"].shape == (3, 20, 30)
    torch.testing.assert_close(item["image"], torch.full((3, 20, 30), 128 / 255))
    assert int(item["mask"].sum()) == 20 * 30 // 4
    up = ViewDataset(ViewManifest.from_csv(tmp_path / "m.csv"), size=(80, 120))[0]
    assert int(up["mask"].sum()) == 80 * 120 // 4


def test_rgba_alpha_is_the_mask_and_16_bit_is_scaled(tmp_path: Path) -> None:
    rgba = np.zeros((6, 7, 4), np.uint8)
    rgba[..., :3] = 200
    rgba[2:4, 1:5, 3] = 255
    _save(tmp_path / "rgba.png", rgba)
    deep = _gray(3, (6, 7), np.uint16)
    _save(tmp_path / "deep.png", deep)
    _write_csv(tmp_path / "m.csv", ["path,object,azimuth", "rgba.png,a,0", "deep.png,b,0"])
    ds = ViewDataset(ViewManifest.from_csv(tmp_path / "m.csv"))
    item = ds[0]
    assert item["image"].shape == (3, 6, 7)
    np.testing.assert_array_equal(item["mask"][0].numpy(), rgba[..., 3] > 0)
    assert math.isnan(item["elevation"])
    deep_item = ds[1]
    np.testing.assert_allclose(deep_item["image"][0].numpy(), deep / 65535.0, rtol=1e-6)
    assert bool(deep_item["mask"].all())  # no mask, no alpha: all object
    gray = ViewDataset(ViewManifest.from_csv(tmp_path / "m.csv"), channels=3)[1]["image"]
    assert gray.shape == (3, 6, 7) and torch.equal(gray[0], gray[2])
    assert ViewDataset(ViewManifest.from_csv(tmp_path / "m.csv"), channels=1)[0]["image"].shape == (1, 6, 7)


def test_pattern_parses_object_and_angles(tmp_path: Path) -> None:
    for obj in ("mug-2", "toy"):
        for el, az in ((0, 0), (0, 45.5), (30, 0)):
            _save(tmp_path / obj / f"{obj}-{el}-{az}.png", _gray(1))
    _save(tmp_path / "toy" / "other-0-0.png", _gray(1))  # object text must repeat: ignored
    (tmp_path / "notes.txt").write_text("ignored")
    man = ViewManifest.from_pattern(tmp_path, "{object}/{object}-{elevation}-{azimuth}.png")
    assert sorted(man.objects) == ["mug-2", "toy"]
    assert [(v.azimuth, v.elevation) for v in man.views("mug-2")] == [(0.0, 0.0), (0.0, 30.0), (45.5, 0.0)]
    assert len(ViewDataset(man, size=(4, 4))) == 6


@pytest.mark.parametrize(
    ("pattern", "match"),
    [
        ("{object}/{azimut}.png", "unknown field"),
        ("{object}/{elevation}.png", "must name the fields"),
        ("{object}/{azimuth.png", "unmatched brace"),
        ("../{object}-{azimuth}.png", "relative to the root"),
        ("{object}-{azimuth}.jpg", "no file that matches"),
    ],
)
def test_bad_patterns(tmp_path: Path, pattern: str, match: str) -> None:
    _save(tmp_path / "a-0.png", _gray(0))
    with pytest.raises(ValueError, match=match):
        ViewManifest.from_pattern(tmp_path, pattern)


@pytest.mark.parametrize(
    ("rows", "match"),
    [
        (["path,object", "a.png,a"], r"m\.csv line 1: the header must hold .*missing \['azimuth'\]"),
        (
            ["path,object,azimuth", "a.png,a,0", "gone.png,a,5"],
            r"m\.csv line 3: image .*gone\.png does not exist",
        ),
        (
            ["path,object,azimuth", "a.png,a,0", "b.png,a,360"],
            r"m\.csv line 3: duplicates the view of .*line 2",
        ),
        (["path,object,azimuth", "a.png,a,ten"], r"m\.csv line 2: azimuth='ten' must be a number"),
        (
            ["path,object,azimuth,elevation", "a.png,a,0,nan"],
            r"m\.csv line 2: elevation='nan' must be a finite",
        ),
        (
            ["path,object,azimuth,mask", "a.png,a,0,nomask.png"],
            r"m\.csv line 2: mask .*nomask\.png does not exist",
        ),
        (["path,object,azimuth", "a.png,,0"], r"m\.csv line 2: object must be a non-empty name"),
        (["path,object,azimuth", "a.png,a"], r"m\.csv line 2: has 2 fields"),
    ],
)
def test_bad_manifest_lines_name_file_and_line(tmp_path: Path, rows: list[str], match: str) -> None:
    _save(tmp_path / "a.png", _gray(0))
    _save(tmp_path / "b.png", _gray(1))
    with pytest.raises(ValueError, match=match):
        ViewManifest.from_csv(_write_csv(tmp_path / "m.csv", rows))


def test_mask_of_another_size_names_line_and_files(tmp_path: Path) -> None:
    _save(tmp_path / "a.png", _gray(0, (12, 16)))
    _save(tmp_path / "a-mask.png", _gray(0, (12, 15)))
    man = ViewManifest.from_csv(
        _write_csv(tmp_path / "m.csv", ["path,object,azimuth,mask", "a.png,a,0,a-mask.png"])
    )
    with pytest.raises(ValueError, match=r"m\.csv line 2: mask .*a-mask\.png has size .*a\.png"):
        ViewDataset(man, size=(12, 16))[0]


def test_bad_dataset_arguments(views: Path) -> None:
    man = ViewManifest.from_csv(views)
    with pytest.raises(ValueError, match="size"):
        ViewDataset(man, size=(0, 4))
    with pytest.raises(TypeError, match="size"):
        ViewDataset(man, size=8)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="channels"):
        ViewDataset(man, channels=2)
    with pytest.raises(TypeError, match="manifest"):
        ViewDataset(views)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="object='jug' is not in"):
        man.views("jug")


def test_coil_manifest_gives_coilfolder_tensors(coil_root: Path, folder: CoilFolder) -> None:
    man = ViewManifest.from_coil(coil_root)
    assert man.objects == [str(o) for o in folder.objects]
    assert [v.azimuth for v in man.views("3")] == folder.poses(3)
    ds = ViewDataset(man)
    index = {(e.object, e.azimuth): i for i, e in enumerate(man)}
    for obj, degrees in ((1, [0.0, 5.0, 355.0]), (7, [90.0]), (20, [180.0, 245.0])):
        expected = folder.images(obj, degrees)
        got = torch.stack([ds[index[(str(obj), d)]]["image"] for d in degrees])
        assert got.dtype == expected.dtype
        assert torch.equal(got, expected)


def test_skipped_collects_bad_lines_and_keeps_the_rest(tmp_path: Path) -> None:
    _save(tmp_path / "a.png", _gray(0))
    rows = [
        "path,object,azimuth",
        "a.png,a,0",
        "gone.png,a,5",
        "a.png,a,ten",
        "a.png,a,360",
        "a.png,a,10",
        "x",
    ]
    skipped: list[str] = []
    man = ViewManifest.from_csv(_write_csv(tmp_path / "m.csv", rows), skipped=skipped)
    assert [e.azimuth for e in man] == [0.0, 10.0]
    assert [s.split(": ")[0] for s in skipped] == [f"{tmp_path / 'm.csv'} line {n}" for n in (3, 4, 7, 5)]
    assert "gone.png does not exist" in skipped[0] and "azimuth='ten'" in skipped[1]
    assert "has 1 fields" in skipped[2] and "duplicates the view of" in skipped[3]
    with pytest.raises(ValueError, match="lists no view"):
        ViewManifest.from_csv(
            _write_csv(tmp_path / "n.csv", ["path,object,azimuth", "gone.png,a,0"]), skipped=[]
        )


def test_read_view_without_source_names_the_file(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"^image .*nothing\.png does not exist$"):
        read_view(tmp_path / "nothing.png")
