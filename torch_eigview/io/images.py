"""Reading image files as ``(C, H, W)`` arrays, without torch.

Shared by :class:`~torch_eigview.datasets.coil.CoilFolder` and the torch-free ``eigview predict``
(onnxruntime), so both see exactly the same pixels: grayscale gives ``C = 1``, RGB ``C = 3``,
an alpha channel is dropped; ``uint8`` is divided by 255, ``uint16`` by 65535, float images
are kept as they are.
"""

from __future__ import annotations

import os

import numpy as np
import skimage.io

__all__ = ["read_image", "to_unit_float"]


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Reads one file as a checked ``(C, H, W)`` array of its own dtype (alpha dropped).

    Raises:
        ValueError: the file cannot be decoded, or its layout or dtype is not an image's.
    """
    try:
        arr = np.asarray(skimage.io.imread(path))
    except Exception as exc:  # imageio/PIL raise OSError, SyntaxError, ... for bad files
        raise ValueError(f"cannot read image {path}: {exc}") from exc
    if arr.ndim == 2:
        arr = arr[None]
    elif arr.ndim == 3 and arr.shape[-1] in (1, 2, 3, 4):
        # Channels 2 and 4 are alpha (gray+alpha, RGBA): dropped.
        keep = {1: 1, 2: 1, 3: 3, 4: 3}[arr.shape[-1]]
        arr = np.ascontiguousarray(np.moveaxis(arr[..., :keep], -1, 0))
    else:
        raise ValueError(f"image {path} must be (H, W) or (H, W, 1..4), got shape {arr.shape}")
    if arr.dtype.kind not in "buf":
        raise ValueError(f"image {path} must hold unsigned or float pixels, got dtype {arr.dtype}")
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise ValueError(f"image {path} must be finite, got NaN or infinite pixels")
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
