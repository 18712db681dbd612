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


def test_multi_page_tiff_refused_undecoded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Refused from its header: the pages are never decoded."""
    path = tmp_path / "pages.tif"
    with tifffile.TiffWriter(path) as tif:
        for _ in range(3):
            tif.write(np.zeros((4, 5), dtype=np.uint8))

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("a refused file was decoded")

    monkeypatch.setattr(skimage.io, "imread", refuse)
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


def _pillow_images() -> dict[str, object]:
    from PIL import Image

    rng = np.random.default_rng(0)

    def u8(*shape: int) -> np.ndarray:
        return rng.integers(0, 256, shape, dtype=np.uint8)

    palette = Image.fromarray(u8(7, 5, 3), "RGB").convert("P")
    clear = palette.copy()
    clear.info["transparency"] = clear.getpixel((0, 0))
    return {
        "L": Image.fromarray(u8(7, 5), "L"),
        "LA": Image.fromarray(u8(7, 5, 2), "LA"),
        "RGB": Image.fromarray(u8(7, 5, 3), "RGB"),
        "RGBA": Image.fromarray(u8(7, 5, 4), "RGBA"),
        "I16": Image.fromarray(rng.integers(0, 65536, (7, 5), dtype=np.uint16)),
        "P": palette,
        "P-transparent": clear,
        "1": Image.fromarray(u8(7, 5) // 128 * 255, "L").convert("1"),
    }


# Every mode in the formats Pillow can write it to (JPEG holds no alpha, BMP no gray + alpha
# or 16-bit gray, webp is RGB(A)); a palette with a transparent entry has its own test.
_WRITABLE = [(m, "png") for m in _pillow_images() if m != "P-transparent"] + [
    *((m, "bmp") for m in ("L", "RGB", "RGBA", "P", "1")),
    *((m, "jpg") for m in ("L", "RGB", "1")),
    *((m, "webp") for m in ("L", "LA", "RGB", "RGBA", "P")),
]


@pytest.mark.parametrize(("mode", "suffix"), _WRITABLE)
def test_pillow_decoding_matches_skimage(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, mode: str, suffix: str
) -> None:
    """The Pillow path (scikit-image's reader is never called) gives what skimage.io.imread,
    the reference, gives, dtype included, in an array of the caller's own."""
    path = tmp_path / f"{mode}.{suffix}"
    _pillow_images()[mode].save(path)  # type: ignore[attr-defined]
    reference = np.asarray(skimage.io.imread(path))
    reference = reference[None] if reference.ndim == 2 else np.moveaxis(reference, -1, 0)

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("skimage.io.imread was called for a mode Pillow decodes")

    monkeypatch.setattr(skimage.io, "imread", refuse)
    got = read_image(path, keep_alpha=True)
    assert got.dtype == reference.dtype and got.flags.writeable
    np.testing.assert_array_equal(got, reference)


def test_transparent_palette_keeps_its_alpha(tmp_path: Path) -> None:
    """A palette PNG with a transparent entry: its colours as scikit-image gives them, and
    with keep_alpha the transparency as alpha (Pillow's RGBA, the reference)."""
    from PIL import Image

    path = tmp_path / "cutout.png"
    _pillow_images()["P-transparent"].save(path)  # type: ignore[attr-defined]
    np.testing.assert_array_equal(read_image(path), np.moveaxis(skimage.io.imread(path), -1, 0))
    with Image.open(path) as im:
        rgba = np.moveaxis(np.asarray(im.convert("RGBA")), -1, 0)
    got = read_image(path, keep_alpha=True)
    np.testing.assert_array_equal(got, rgba)
    assert got[3, 0, 0] == 0 and (got[3] == 255).any()  # the first pixel's entry is see-through


def test_cmyk_read_as_rgb(tmp_path: Path) -> None:
    """A CMYK JPEG is its RGB (Pillow's conversion, the reference), never its four raw
    channels (whose K was once taken for alpha)."""
    from PIL import Image

    path = tmp_path / "cmyk.jpg"
    _pillow_images()["RGB"].convert("CMYK").save(path)  # type: ignore[attr-defined]
    with Image.open(path) as im:
        assert im.mode == "CMYK"
        rgb = np.moveaxis(np.asarray(im.convert("RGB")), -1, 0)
    got = read_image(path, keep_alpha=True)
    assert got.shape == (3, 7, 5)
    np.testing.assert_array_equal(got, rgb)


def test_one_frame_gif_read_as_rgb(tmp_path: Path) -> None:
    """A one-frame GIF (which skimage reads as (1, H, W, 3)) is an RGB image of its palette."""
    path = tmp_path / "one.gif"
    _pillow_images()["RGB"].save(path)  # type: ignore[attr-defined]
    got = read_image(path)
    assert got.shape == (3, 7, 5) and got.dtype == np.uint8
    np.testing.assert_array_equal(got, np.moveaxis(np.asarray(skimage.io.imread(path))[0], -1, 0))


def test_animated_gif_refused(tmp_path: Path) -> None:
    from PIL import Image

    frames = [Image.fromarray(np.full((4, 5), v, dtype=np.uint8), "L") for v in (0, 128, 255)]
    path = tmp_path / "anim.gif"
    frames[0].save(path, save_all=True, append_images=frames[1:])
    with pytest.raises(ValueError, match=r"anim\.gif holds 3 pages or frames"):
        read_image(path)


def test_corrupt_png_named(tmp_path: Path) -> None:
    path = _png(tmp_path / "cut.png")
    path.write_bytes(path.read_bytes()[:40])
    with pytest.raises(ValueError, match=r"cut\.png is not an image file that can be read.*broken PNG"):
        read_image(path)


def test_unknown_format_named(tmp_path: Path) -> None:
    path = tmp_path / "noise.png"
    path.write_bytes(b"not an image at all")
    with pytest.raises(
        ValueError, match=r"noise\.png is not an image file that can be read.*no reader recognizes"
    ):
        read_image(path)


def test_coil_images_match_skimage(coil_root: Path) -> None:
    files = sorted(Path(coil_root).glob("obj1__*.png"))[:6]
    for path in files:
        np.testing.assert_array_equal(read_image(path)[0], skimage.io.imread(path))
