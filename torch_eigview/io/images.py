"""Reading image files as ``(C, H, W)`` arrays, without torch.

Shared by :class:`~torch_eigview.datasets.coil.CoilFolder` and the torch-free ``eigview predict``
(onnxruntime), so both see exactly the same pixels: grayscale gives ``C = 1``, RGB ``C = 3``,
an alpha channel is dropped; ``uint8`` is divided by 255, ``uint16`` by 65535, float images
are kept as they are and must lie in ``[0, 1]``. Special files (FIFOs, devices, folders) are
refused before they are opened, and a file of several pages is refused.

Decoding: Pillow opens a file once, counts its frames and hands over the pixels of the
modes whose array is the one ``skimage.io.imread`` gives (8-bit gray, gray + alpha, RGB,
RGBA, 16-bit gray, bilevel; palette images expanded to their palette's colours, as
imageio does). Two differ from scikit-image's, on purpose: a palette image with a
transparent entry keeps it as alpha (RGBA, so that a cut-out saved as an 8-bit PNG keeps
its mask; scikit-image gives its RGB alone), and a CMYK image (a print JPEG) is converted
to RGB (scikit-image hands over its four raw channels, whose K was taken for alpha). TIFF
and every other file go to ``skimage.io.imread``, imported only then: its import is heavy
(scikit-image and imageio's plugins), and for the common formats it only adds layers over
the Pillow decoder that reads them. The arrays are the caller's own (writable), as
scikit-image's are.
"""

from __future__ import annotations

import os
import stat

import numpy as np

__all__ = ["check_regular_file", "image_size", "read_image", "to_unit_float"]

_TIFF_SUFFIXES = (".tif", ".tiff")

#: Pillow modes whose ``np.asarray`` equals ``skimage.io.imread``'s array (tests check it).
_PIL_MODES = frozenset({"L", "LA", "RGB", "RGBA", "I;16", "1"})


def check_regular_file(path: str | os.PathLike[str], what: str = "image") -> os.stat_result:
    """Checks with ``os.stat``, before anything opens it, that ``path`` is a regular file.

    A FIFO would block the reader forever, a device could stream without end, and a
    directory or a symlink loop cannot be an image: each is refused, never opened.

    Returns:
        The file's ``os.stat`` result.

    Raises:
        ValueError: ``path`` is missing, unreadable, a symlink loop, or not a regular file;
            the message names it and what it is.
    """
    try:
        info = os.stat(path)  # follows symlinks; a loop raises ELOOP
    except FileNotFoundError:
        raise ValueError(f"{what} {os.fspath(path)!s} does not exist") from None
    except OSError as exc:
        raise ValueError(f"{what} {os.fspath(path)!s} cannot be used: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        kind = (
            "a directory"
            if stat.S_ISDIR(info.st_mode)
            else "a FIFO (named pipe)"
            if stat.S_ISFIFO(info.st_mode)
            else "a device"
            if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode)
            else "a socket or other special file"
        )
        raise ValueError(f"{what} {os.fspath(path)!s} is {kind}, not a regular file: refused, never opened")
    return info


def _decode(path: str | os.PathLike[str]) -> tuple[np.ndarray | None, int]:
    """The pixels and the number of pages or frames of one file (see the module's docstring);
    a file of several is never decoded (None: it is refused, and a stack of large pages
    would cost their memory first)."""
    if os.fspath(path).lower().endswith(_TIFF_SUFFIXES):
        import tifffile

        with tifffile.TiffFile(path) as tif:
            frames = len(tif.pages)
    else:
        pixels, frames = _decode_pillow(path)
        if pixels is not None:
            return pixels, frames
    if frames > 1:
        return None, frames
    import skimage.io

    return np.asarray(skimage.io.imread(path)), frames


def _decode_pillow(path: str | os.PathLike[str]) -> tuple[np.ndarray | None, int]:
    """Pillow's pixels in the modes of :data:`_PIL_MODES` (a palette or CMYK image converted
    first; None in the other modes) and the number of frames."""
    from PIL import Image

    try:
        im = Image.open(path)
    except Exception:  # not a format Pillow knows: scikit-image's readers may know it
        return None, 1
    with im:
        frames = int(getattr(im, "n_frames", 1))
        if frames > 1:
            return None, frames
        colours: Image.Image = im
        if im.mode == "P" and im.palette is not None:
            # A palette image as its colours, with alpha where an entry is transparent.
            colours = im.convert("RGBA" if "transparency" in im.info else im.palette.mode)
        elif im.mode == "CMYK":
            colours = im.convert("RGB")
        if colours.mode not in _PIL_MODES:
            return None, frames
        # Pillow's buffer is read-only; the caller gets its own array, as from scikit-image.
        return np.array(colours), frames


def image_size(path: str | os.PathLike[str]) -> tuple[int, int] | None:
    """(H, W) of an image file from its header, nothing decoded; None where Pillow does
    not know the format or cannot open the file (:func:`read_image` then says why)."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            w, h = im.size
    except Exception:
        return None
    return int(h), int(w)


def read_image(path: str | os.PathLike[str], *, keep_alpha: bool = False, what: str = "image") -> np.ndarray:
    """Reads one file as a checked ``(C, H, W)`` array of its own dtype (alpha dropped).

    With ``keep_alpha=True`` an alpha channel is kept as the last channel (gray+alpha gives
    ``C = 2``, RGBA ``C = 4``), for callers that use it as the foreground mask. The path is checked to be a regular file before it is opened
    (:func:`check_regular_file`); a multi-page TIFF or an animated image is refused rather
    than read as its first page, and float pixels must lie in ``[0, 1]``.

    ``what`` names the file in the errors of :func:`check_regular_file` (``"mask"``).

    Raises:
        ValueError: a special file, a file that cannot be decoded, several pages, a layout
            or dtype that is not an image's, or float pixels outside ``[0, 1]``.
    """
    info = check_regular_file(path, what)
    if info.st_size == 0:
        raise ValueError(f"{what} {os.fspath(path)} is empty (0 bytes): not an image file")
    try:
        arr, frames = _decode(path)
    except Exception as exc:  # imageio/PIL raise OSError, SyntaxError, ... for bad files
        # The cause a user can act on is that the bytes are no image these readers know; the
        # decoder's first line says where it stopped, and imageio's advice to install video
        # plugins for an unknown file is left out (it would only mislead).
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if "Could not find a backend" in detail:
            detail = "no reader recognizes its contents"
        raise ValueError(
            f"{what} {os.fspath(path)} is not an image file that can be read (damaged, truncated, or "
            f"another kind of file; PNG, JPEG, TIFF, BMP and the other raster formats Pillow reads are "
            f"supported): {detail}"
        ) from exc
    if frames > 1 or arr is None:
        raise ValueError(f"image {path} holds {frames} pages or frames; one image per file is expected")
    if arr.ndim == 2:
        arr = arr[None]
    elif arr.ndim == 3 and arr.shape[-1] in (1, 2, 3, 4):
        # Channels 2 and 4 are alpha (gray+alpha, RGBA): dropped.
        keep = arr.shape[-1] if keep_alpha else {1: 1, 2: 1, 3: 3, 4: 3}[arr.shape[-1]]
        arr = np.ascontiguousarray(np.moveaxis(arr[..., :keep], -1, 0))
    else:
        raise ValueError(f"image {path} must be (H, W) or (H, W, 1..4), got shape {arr.shape}")
    if arr.dtype.kind not in "buf":
        raise ValueError(f"image {path} must hold unsigned or float pixels, got dtype {arr.dtype}")
    if arr.dtype.kind == "f":
        if not np.isfinite(arr).all():
            raise ValueError(f"image {path} must be finite, got NaN or infinite pixels")
        lo, hi = (float(arr.min()), float(arr.max())) if arr.size else (0.0, 0.0)
        if lo < 0.0 or hi > 1.0:
            # Intensities are in [0, 1]; a float image outside it is not one (rescaling it
            # would hide the error, e.g. a 1e32-valued TIFF read as black).
            raise ValueError(
                f"image {path} has float values outside [0, 1] (min {lo:.6g}, max {hi:.6g}); "
                "float images must hold intensities in [0, 1]"
            )
    return arr


def to_unit_float(arr: np.ndarray, dtype: type[np.floating] = np.float32) -> np.ndarray:
    """Pixels of :func:`read_image` as floats in ``[0, 1]`` (unsigned ints divided by their maximum).

    Computed in at least float32 (65535 overflows float16), then cast to ``dtype``.
    """
    work = np.float64 if dtype == np.float64 else np.float32
    out = arr.astype(work)
    if arr.dtype.kind == "u":
        out = out / np.asarray(np.iinfo(arr.dtype).max, dtype=work)
    return out.astype(dtype, copy=False)
