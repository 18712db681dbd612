"""A turntable data set of the kind users bring, rendered: many objects, a view every
22.5°, RGB on a coloured, textured backdrop, a mask per view, listed in a manifest.

``python benchmarks/_turntable.py OUT --objects 80 --size 128`` writes
``OUT/views.csv`` (``path,object,azimuth,mask``) and the PNG files. The objects are the
renderer's five shapes, each with textures of several seeds (``shape-seed`` names them);
the backdrop is :class:`~torch_eigview.datasets.Backdrop`'s blue cloth and wooden ground,
whose colours set the gray objects apart, and the masks are the renderer's own.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import skimage.io

from torch_eigview.datasets import SHAPES, Backdrop, OrthographicCamera, make_object
from torch_eigview.datasets.renderer import render_many

__all__ = ["write_turntable"]


def write_turntable(out: Path, objects: int, size: int, step: float = 22.5) -> Path:
    """Renders ``objects`` objects, one view every ``step`` degrees round the turntable,
    ``size`` × ``size`` RGB with masks, into ``out``; returns the manifest's path."""
    out.mkdir(parents=True, exist_ok=True)
    camera = OrthographicCamera(size, 0.3 * size)  # the object spans about 60 % of the side
    backdrop = Backdrop()
    angles = [step * i for i in range(round(360 / step))]
    rows = ["path,object,azimuth,mask"]
    for index in range(objects):
        shape, seed = SHAPES[index % len(SHAPES)], index // len(SHAPES)
        name = f"{shape}-{seed}"
        folder = out / name
        folder.mkdir(exist_ok=True)
        for angle, render in zip(
            angles, render_many(make_object(shape, seed), angles, camera, backdrop=backdrop), strict=True
        ):
            image = (render.image.permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
            mask = (render.mask.numpy() * 255).astype(np.uint8)
            stem = f"{angle:05.1f}"
            skimage.io.imsave(folder / f"{stem}.png", image, check_contrast=False)
            skimage.io.imsave(folder / f"{stem}_mask.png", mask, check_contrast=False)
            rows.append(f"{name}/{stem}.png,{name},{angle:g},{name}/{stem}_mask.png")
    manifest = out / "views.csv"
    manifest.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return manifest


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the folder to write")
    parser.add_argument("--objects", type=int, default=80)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--step", type=float, default=22.5, help="degrees between views")
    args = parser.parse_args(argv)
    print(write_turntable(args.out, args.objects, args.size, args.step))
    return 0


if __name__ == "__main__":
    sys.exit(main())
