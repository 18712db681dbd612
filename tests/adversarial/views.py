"""The files the cases of ``eigview fit`` / ``evaluate`` / ``predict --model`` start from: a
small manifest of rendered objects (32 x 32) and one model fitted on it, made once and copied.
"""

from __future__ import annotations

import contextlib
import functools
import io
import shutil
import tempfile
from pathlib import Path

import numpy as np
import skimage.io

from torch_eigview.apps.cli import main

SIDE = 32
AZIMUTHS = (0, 10, 20)
OBJECTS = ("egg", "head")


@functools.cache
def _rendered() -> dict[tuple[str, int], np.ndarray]:
    """(object, azimuth) -> 8-bit gray image (SIDE, SIDE), rendered once."""
    from torch_eigview.datasets import OrthographicCamera, make_object, render_views

    out = {}
    for name in OBJECTS:
        images = render_views(make_object(name, seed=1), list(AZIMUTHS), OrthographicCamera(SIDE))
        for az, image in zip(AZIMUTHS, images, strict=True):
            out[name, az] = (image[0].clamp(0, 1).numpy() * 255).round().astype(np.uint8)
    return out


def png(path: Path, array: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    skimage.io.imsave(path, array, check_contrast=False)
    return path


def manifest(tmp: Path, extra: str = "", header: str = "path,object,azimuth") -> Path:
    """views.csv listing every rendered view as ``{object}/{azimuth}.png``, then ``extra`` rows."""
    rows = [header]
    for (name, az), image in _rendered().items():
        png(tmp / name / f"{az}.png", image)
        rows.append(f"{name}/{az}.png,{name},{az}")
    path = tmp / "views.csv"
    path.write_text("\n".join(rows) + "\n" + extra, encoding="utf-8")
    return path


def csv(tmp: Path, content: str, name: str = "m.csv", encoding: str = "utf-8") -> Path:
    """``name`` holding ``content`` (bytes written as given), beside the rendered views."""
    manifest(tmp)
    path = tmp / name
    path.write_bytes(content.encode(encoding))
    return path


FIT = ("--seeds", "0", "10", "--synth", "-10", "10", "5", "--reject-poses", "-10", "10", "2.5", "--quiet")


@functools.cache
def _fitted() -> bytes:
    """The bytes of one model that ``eigview fit`` wrote from :func:`manifest`, made once."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "model.pt"
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            status = main(["fit", "--manifest", str(manifest(Path(tmp))), *FIT, "-k", "4", "--out", str(out)])
        assert status == 0, "the shared model could not be fitted"
        return out.read_bytes()


def model(tmp: Path) -> Path:
    """model.pt (from ``eigview fit``) and the views.csv it was fitted on, in ``tmp``."""
    manifest(tmp)
    path = tmp / "model.pt"
    path.write_bytes(_fitted())
    return path


def copy_tree(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst
