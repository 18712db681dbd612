"""read_image and check_regular_file: special files refused unopened, multi-page files and
float pixels outside [0, 1] refused."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
import pytest
import skimage.io
import tifffile

from torch_eigview.io.images import check_regular_file, read_image


def _png(path: Path) -> Path:
    skimage.io.imsave(path, np.zeros((4, 5), dtype=np.uint8), check_contrast=False)
    return path


def test_regular_file_passes(tmp_path: Path) -> None:
    path = _png(tmp_path / "a.png")
    assert check_regular_file(path).st_size > 0
    assert read_image(path).shape == (1, 4, 5)


def test_fifo_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "obj1__0.png"
    os.mkfifo(fifo)
    result: list[BaseException] = []

    def read() -> None:
        try:
            read_image(fifo)
        except ValueError as exc:
            result.append(exc)

    # Opening a FIFO for reading blocks until a writer comes: run in a thread with a deadline.
    worker = threading.Thread(target=read, daemon=True)
    worker.start()
    worker.join(timeout=10)
    assert not worker.is_alive(), "read_image opened the FIFO and blocked"
    assert "is a FIFO (named pipe), not a regular file" in str(result[0]) and "obj1__0.png" in str(result[0])


@pytest.mark.parametrize(
    ("make", "kind"),
    [
        (lambda p: p.mkdir(), "is a directory"),
        (lambda p: os.symlink(p, p), "Too many levels of symbolic links"),
        (lambda p: None, "does not exist"),
    ],
    ids=["directory", "symlink-loop", "missing"],
)
def test_special_entries_named(tmp_path: Path, make: object, kind: str) -> None:
    path = tmp_path / "x.png"
    make(path)  # type: ignore[operator]
    with pytest.raises(ValueError, match=kind) as info:
        read_image(path)
    assert "x.png" in str(info.value)


def test_device_refused() -> None:
    with pytest.raises(ValueError, match="/dev/null is a device, not a regular file"):
        read_image("/dev/null")


def test_multi_page_tiff_refused(tmp_path: Path) -> None:
    path = tmp_path / "pages.tif"
    with tifffile.TiffWriter(path) as tif:
        for _ in range(3):
            tif.write(np.zeros((4, 5), dtype=np.uint8))
    with pytest.raises(ValueError, match=r"pages\.tif holds 3 pages or frames"):
        read_image(path)


@pytest.mark.parametrize("value", [1e32, -0.5, 1.0 + 1e-6])
def test_float_outside_unit_interval_refused(tmp_path: Path, value: float) -> None:
    path = tmp_path / "big.tif"
    tifffile.imwrite(path, np.full((4, 5), value, dtype=np.float32))
    with pytest.raises(ValueError, match=r"big\.tif has float values outside \[0, 1\]"):
        read_image(path)


def test_float_in_unit_interval_kept(tmp_path: Path) -> None:
    path = tmp_path / "ok.tif"
    pixels = np.linspace(0, 1, 20, dtype=np.float32).reshape(4, 5)
    tifffile.imwrite(path, pixels)
    np.testing.assert_array_equal(read_image(path)[0], pixels)
