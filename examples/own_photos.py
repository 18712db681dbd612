"""Your own photographs, end to end: image files and a manifest through ``eigview fit`` and ``evaluate``.

The five synthetic objects stand in for a user's turntable photographs: rendered at 64×64
with the object well inside the frame (``--scale``: an object of radius 1 spans 60% of the
side by default), on the coloured, textured backdrop and ground of
:class:`~torch_eigview.datasets.backdrop.Backdrop`, and written as PNG files with a CSV
manifest (``path,object,azimuth[,mask]``) into a temporary folder. Each kind of files is
then fitted from the views at 0° and 10° (Fig. 2's α = 10, two views) and evaluated on the
rendered views over ``--test`` (every ``--step`` degrees), with the same command line:

- ``black``: the same views on a black background, ``--background keep`` (the reference);
- ``masks``: the backdrop, RGB 8-bit, a mask PNG per view (the ``mask`` column), ``--background auto``;
- ``estimated``: the backdrop without masks, ``--background auto`` (the foreground from the border's colours);
- ``16-bit``: as ``masks`` with 16-bit RGB TIFF files (Pillow reads a 16-bit RGB PNG as
  8-bit, so 16-bit colour goes through TIFF);
- ``rgba``: the backdrop as RGBA PNGs whose alpha is the mask, ``--background auto``.

Prints the accuracy of each, its pose error and its difference to ``black``.

Run: ``python examples/own_photos.py [--objects ...] [--test -45 44] [--step 1] [--json out.json]``
"""

from __future__ import annotations

import argparse
import csv
import json
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import skimage.io
import tifffile
import torch

from torch_eigview.apps.cli import main as eigview
from torch_eigview.datasets import SHAPES, Backdrop, OrthographicCamera, make_object, render
from torch_eigview.geometry.angles import angle_range

# name -> (backdrop, file kind, mask column, --background)
KINDS = {
    "black": (False, "gray8", False, "keep"),
    "masks": (True, "rgb8", True, "auto"),
    "estimated": (True, "rgb8", False, "auto"),
    "16-bit": (True, "rgb16", True, "auto"),
    "rgba": (True, "rgba8", False, "auto"),
}
SEEDS = (0.0, 10.0)


def render_views(
    shapes: Sequence[str], angles: Sequence[float], size: int, scale: float
) -> dict[tuple[str, float], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per (object, angle): the black-background view (H, W), the backdrop view (H, W, 3)
    and the exact mask (H, W), floats in [0, 1] and bool."""
    camera = OrthographicCamera(size, scale=scale * size / 2)
    backdrop = Backdrop()
    out = {}
    for name in shapes:
        obj = make_object(name, 0)
        for a in angles:
            black = render(obj, a, camera).image[0].numpy()
            on = render(obj, a, camera, backdrop=backdrop)
            out[name, a] = (black, on.image.permute(1, 2, 0).numpy(), on.mask.numpy())
    return out


def _pixels(image: np.ndarray, mask: np.ndarray, kind: str) -> np.ndarray:
    if kind == "rgb16":
        return np.round(image * 65535).astype(np.uint16)
    u8 = np.round(image * 255).astype(np.uint8)
    if kind == "rgba8":
        return np.dstack([u8, np.where(mask, 255, 0).astype(np.uint8)])
    return u8


def write_kind(folder: Path, kind: str, views: dict[tuple[str, float], tuple[np.ndarray, ...]]) -> Path:
    """Writes one kind's image files (and masks) and its manifest; returns the manifest."""
    backdrop, files, with_masks, _ = KINDS[kind]
    folder.mkdir(parents=True)
    rows = []
    for (name, a), (black, colour, mask) in views.items():
        stem = f"{name}_{a:g}"
        image = colour if backdrop else black
        path = f"{stem}.tif" if files == "rgb16" else f"{stem}.png"
        pixels = _pixels(image, mask, files)
        if files == "rgb16":
            tifffile.imwrite(folder / path, pixels, photometric="rgb")
        else:
            skimage.io.imsave(folder / path, pixels, check_contrast=False)
        row = {"path": path, "object": name, "azimuth": f"{a % 360:g}"}
        if with_masks:
            skimage.io.imsave(folder / f"{stem}_mask.png", mask.astype(np.uint8) * 255, check_contrast=False)
            row["mask"] = f"{stem}_mask.png"
        rows.append(row)
    manifest = folder / "views.csv"
    with open(manifest, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return manifest


def run_kind(manifest: Path, kind: str, fit_args: Sequence[str]) -> dict[str, object]:
    """``eigview fit`` and ``eigview evaluate`` on one manifest; the evaluation's JSON."""
    folder = manifest.parent
    seeds = [f"{s:g}" for s in SEEDS]
    fit = [
        "fit",
        "--manifest",
        str(manifest),
        "--seeds",
        *seeds,
        "--channels",
        "1",
        "--background",
        KINDS[kind][3],
    ]
    if eigview([*fit, *fit_args, "--quiet", "--out", str(folder / "model.pt")]) != 0:
        raise RuntimeError(f"eigview fit failed on {kind}")
    out = folder / "result.json"
    if eigview(
        [
            "evaluate",
            "--model",
            str(folder / "model.pt"),
            "--manifest",
            str(manifest),
            "--quiet",
            "--json",
            str(out),
        ]
    ):
        raise RuntimeError(f"eigview evaluate skipped rows on {kind}")
    return json.loads(out.read_text())


def main(argv: Sequence[str] | None = None) -> list[dict[str, object]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", nargs="+", choices=SHAPES, default=list(SHAPES))
    parser.add_argument("--kinds", nargs="+", choices=list(KINDS), default=list(KINDS))
    parser.add_argument("--size", type=int, default=64, help="image side in pixels")
    parser.add_argument("--scale", type=float, default=0.6, help="the object's diameter / the image side")
    parser.add_argument("--test", type=float, nargs=2, default=(-45.0, 44.0), metavar=("START", "STOP"))
    parser.add_argument("--step", type=float, default=1.0, help="degrees between test views")
    parser.add_argument(
        "--fit-args",
        default="--elevation 0 --silhouette",
        help="further eigview fit options, the same for every kind: the renders' camera is untilted, and "
        "their objects do not fill the frame, so --extent auto (the default) leaves the synthesized views unnormalized",
    )
    parser.add_argument("--json", help="write the table here")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    angles = sorted(set(angle_range(args.test[0], args.test[1], args.step, "--test")) | set(SEEDS))
    t0 = time.perf_counter()
    views = render_views(args.objects, angles, args.size, args.scale)
    print(f"rendered {len(views)} views in {time.perf_counter() - t0:.1f} s", flush=True)
    rows: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            result = run_kind(write_kind(Path(tmp) / kind, kind, views), kind, args.fit_args.split())
            pose = result["pose_error_deg"]
            assert isinstance(pose, dict)
            rows.append({"kind": kind, "background": KINDS[kind][3], "accuracy": result["accuracy"],
                         "pose_mean_deg": pose["mean"], "n_test": result["n_test"]})  # fmt: skip
    black = next((r["accuracy"] for r in rows if r["kind"] == "black"), None)
    print(
        f"{'files':>10} {'--background':>12} {'accuracy (%)':>13} {'vs black':>9} {'pose err':>9} {'views':>6}"
    )
    for r in rows:
        acc = float(r["accuracy"])  # type: ignore[arg-type]
        delta = f"{acc - float(black):+9.2f}" if black is not None else f"{'':>9}"
        print(
            f"{r['kind']:>10} {r['background']:>12} {acc:13.2f} {delta} {r['pose_mean_deg']:9.2f} {r['n_test']:6}"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))
    return rows


if __name__ == "__main__":
    main()
