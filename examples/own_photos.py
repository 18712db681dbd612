"""Your own photographs, end to end in Python: image files and a manifest, fitted, saved, loaded and predicted.

The five synthetic objects stand in for a user's turntable photographs: rendered at 64×64
with the object well inside the frame (``--scale``: an object of radius 1 spans 60% of the
side by default), on the coloured, textured backdrop and ground of
:class:`~torch_eigview.datasets.backdrop.Backdrop`, and written as PNG files with a CSV
manifest (``path,object,azimuth[,mask]``) into a temporary folder. Each kind of files is
then fitted from the views at 0° and 10° (Fig. 2's α = 10, two views) with
``FewViewEigenspace.fit_manifest`` (the path ``eigview fit`` takes), saved with ``save`` (the
file ``eigview predict --model`` reads), loaded with ``load_model`` and asked for the other
views with ``predict_files``, with the same settings for every kind:

- ``black``: the same views on a black background, ``--background keep`` (the reference);
- ``masks``: the backdrop, RGB 8-bit, a mask PNG per view (the ``mask`` column), ``--background auto``;
- ``estimated``: the backdrop without masks, ``--background auto`` (the foreground from the border's colours);
- ``16-bit``: as ``masks`` with 16-bit RGB TIFF files (Pillow reads a 16-bit RGB PNG as
  8-bit, so 16-bit colour goes through TIFF);
- ``rgba``: the backdrop as RGBA PNGs whose alpha is the mask, ``--background auto``.

The renderer's camera is untilted and its objects do not fill the frame, so the synthesis
is told so (``SynthesisOptions(elevation=0.0, silhouette=True)``: no elevation to estimate,
the synthesized views' size normalized by the silhouette); photographs from a tilted camera
keep the default, ``elevation="auto"``. Prints the accuracy of each on the views other
than the seeds, its pose error and its difference to ``black``.

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

from torch_eigview import FewViewEigenspace, SynthesisOptions
from torch_eigview.datasets import SHAPES, Backdrop, OrthographicCamera, ViewManifest, make_object, render
from torch_eigview.io import load_model

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


def run_kind(manifest: Path, kind: str, options: SynthesisOptions) -> dict[str, object]:
    """Fit on one manifest's seed views, save, load, and predict its other views."""
    views = ViewManifest.from_csv(manifest)
    est = FewViewEigenspace(15, options=options)
    est.fit_manifest(views, list(SEEDS), channels=1, background=KINDS[kind][3])
    est.save(manifest.parent / "model.pt")
    model = load_model(manifest.parent / "model.pt")  # what eigview predict --model reads
    tests = [v for v in views if v.azimuth not in SEEDS]
    found = model.predict_files([v.path for v in tests])
    table = model.label_table()  # object name -> label
    truth = torch.tensor([table[v.object] for v in tests])
    right = found.labels == truth
    error = (
        found.poses - torch.tensor([v.azimuth for v in tests], dtype=found.poses.dtype) + 180
    ) % 360 - 180
    return {
        "accuracy": 100.0 * float(right.float().mean()),
        "pose_mean_deg": float(error[right].abs().mean()) if bool(right.any()) else float("nan"),
        "n_test": len(tests),
    }


def main(argv: Sequence[str] | None = None) -> list[dict[str, object]]:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--objects", nargs="+", choices=SHAPES, default=list(SHAPES))
    parser.add_argument("--kinds", nargs="+", choices=list(KINDS), default=list(KINDS))
    parser.add_argument("--size", type=int, default=64, help="image side in pixels")
    parser.add_argument("--scale", type=float, default=0.6, help="the object's diameter / the image side")
    parser.add_argument("--test", type=float, nargs=2, default=(-45.0, 44.0), metavar=("START", "STOP"))
    parser.add_argument("--step", type=float, default=1.0, help="degrees between test views")
    parser.add_argument("--json", help="write the table here")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    steps = int(np.floor((args.test[1] - args.test[0]) / args.step + 1e-9)) + 1
    angles = sorted({args.test[0] + i * args.step for i in range(steps)} | set(SEEDS))
    # The renders' camera is untilted and their objects do not fill the frame (see above).
    options = SynthesisOptions(elevation=0.0, silhouette=True)
    t0 = time.perf_counter()
    views = render_views(args.objects, angles, args.size, args.scale)
    print(f"rendered {len(views)} views in {time.perf_counter() - t0:.1f} s", flush=True)
    rows: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            result = run_kind(write_kind(Path(tmp) / kind, kind, views), kind, options)
            rows.append({"kind": kind, "background": KINDS[kind][3], **result})
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
