"""CoilFolder's scan: entries named like images that are not files, mixed pose conventions,
and the bound on object selections."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import skimage.io

from torch_eigview.config import config_context
from torch_eigview.datasets.coil import CoilFolder, parse_object_spec


def _write(folder: Path, *names: str) -> None:
    for name in names:
        skimage.io.imsave(folder / name, np.zeros((4, 4), dtype=np.uint8), check_contrast=False)


def test_stray_file_does_not_switch_the_pose_unit(tmp_path: Path) -> None:
    _write(tmp_path, *(f"obj{o}__{p}.png" for o in (1, 2) for p in (0, 1, 2)), "obj1__72.png")
    with pytest.raises(
        ValueError, match=r"mixes pose conventions: objects \[1\] .* in obj1__72\.png"
    ) as info:
        CoilFolder(tmp_path)
    assert "objects [2] have only P < 72" in str(info.value) and "pose_unit" in str(info.value)
    assert CoilFolder(tmp_path, pose_unit="degrees").poses(1) == [0.0, 1.0, 2.0, 72.0]


def test_consistent_conventions(tmp_path: Path) -> None:
    _write(tmp_path, "obj1__0.png", "obj1__90.png", "obj2__0.png", "obj2__180.png")
    assert CoilFolder(tmp_path).pose_unit == "degrees"
    index = tmp_path / "index"
    index.mkdir()
    _write(index, "obj1__0.png", "obj1__71.png", "obj2__3.png")
    assert CoilFolder(index).pose_unit == "index"


@pytest.mark.parametrize(
    ("make", "kind"),
    [
        (os.mkfifo, "is a FIFO"),
        (os.mkdir, "is a directory"),
        (lambda p: os.symlink(p, p), "symbolic links"),
    ],
    ids=["fifo", "directory", "symlink-loop"],
)
def test_entries_named_like_images_are_errors(tmp_path: Path, make: object, kind: str) -> None:
    _write(tmp_path, "obj1__0.png")
    make(tmp_path / "obj1__1.png")  # type: ignore[operator]
    with pytest.raises(
        ValueError,
        match=f"not image files: COIL file .*obj1__1.png {kind}" if kind != "symbolic links" else kind,
    ):
        CoilFolder(tmp_path)


def test_object_spec_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(
        ValueError,
        match=r"asks for 1e\+11 object ids, more than the limit of 100000 \(max_objects\); raise it with torch_eigview.config_context\(max_objects=...\).*EIGVIEW_MAX_OBJECTS",
    ):
        parse_object_spec("1-99999999999")
    with config_context(max_objects=5):
        assert parse_object_spec("1-5") == [1, 2, 3, 4, 5]
        with pytest.raises(ValueError, match="limit of 5"):
            parse_object_spec("1-3,7-9")
    monkeypatch.setenv("EIGVIEW_MAX_OBJECTS", "5")  # the library reads no environment variable
    assert len(parse_object_spec("1-9")) == 9
