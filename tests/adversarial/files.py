"""The files the adversarial cases start from: a tiny COIL folder, a model, its ONNX graph, images."""

from __future__ import annotations

import contextlib
import functools
import io
import os
import tempfile
from pathlib import Path

import numpy as np
import skimage.io
import tifffile
import torch

from torch_eigview.apps.cli import main
from torch_eigview.io.checkpoint import save_recognizer

from tests.io.test_checkpoint import IMAGE_SHAPE, make_recognizer


def coil(tmp: Path, objects: int = 2, poses: int = 72, side: int = 8) -> Path:
    """obj{o}__{p}.png grey images of ``objects`` objects at ``poses`` pose indices (5 degrees apart)."""
    rng = np.random.default_rng(0)
    for o in range(1, objects + 1):
        for p in range(poses):
            image = (rng.random((side, side)) * 255).astype(np.uint8)
            skimage.io.imsave(tmp / f"obj{o}__{p}.png", image, check_contrast=False)
    return tmp


def model(tmp: Path) -> Path:
    """model.pt: a recognizer of (1, 4, 6) images, as ``eigview coil --save`` writes one."""
    path = tmp / "model.pt"
    save_recognizer(make_recognizer(), path)
    return path


@functools.cache
def _exported() -> bytes:
    """The bytes of one export, made once: an export takes seconds, a copy nothing."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.onnx"
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            main(["export", "--model", str(model(Path(tmp))), "--out", str(path), "--recognizer"])
        return path.read_bytes()


def onnx(tmp: Path) -> Path:
    """m.onnx: ``model`` exported with ``--recognizer``."""
    path = tmp / "m.onnx"
    path.write_bytes(_exported())
    return path


def image(
    tmp: Path, name: str = "a.png", shape: tuple[int, ...] = IMAGE_SHAPE[1:], dtype: str = "uint8"
) -> Path:
    """A readable image of ``shape`` (H, W) or (H, W, C) and ``dtype``."""
    path = tmp / name
    values = np.random.default_rng(1).random(shape)
    if dtype == "uint8":
        skimage.io.imsave(path, (values * 255).astype(np.uint8), check_contrast=False)
    elif dtype == "uint16":
        skimage.io.imsave(path, (values * 65535).astype(np.uint16), check_contrast=False)
    else:
        tifffile.imwrite(path, values.astype(dtype), photometric="minisblack")
    return path


def fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def truncated(path: Path) -> Path:
    """``path`` cut to its first half."""
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def text(path: Path, content: str = "not what it should be\n") -> Path:
    path.write_text(content)
    return path


def torch_file(path: Path, payload: object) -> Path:
    torch.save(payload, path)
    return path
