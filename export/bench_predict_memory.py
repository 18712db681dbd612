"""Peak memory (max RSS) of ``eigview predict`` against the number of images.

Not a test: a benchmark to run by hand. It exports a recognizer over random 128×128
gallery views (72 views of 20 labels, k = 15), writes 100 distinct PNG images and hard
links to them up to the largest count (each link is a separate file that predict opens and
decodes), then runs ``python -m torch_eigview.apps.predict`` in a fresh process per count
and reports that process's peak resident set size (``VmHWM``, Linux) and the
ratio of each count's peak to the smallest count's. Counts run in the order given; every
count is one child process, so the peaks do not contaminate each other. Run:
``python export/bench_predict_memory.py [--counts 100 1440 14400]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import skimage.io
import torch

from torch_eigview.decomposition import Eigenspace
from torch_eigview.io.onnx import export_recognizer
from torch_eigview.nn.recognition import NearestNeighborRecognizer

SIDE = 128


def make_model(folder: Path) -> Path:
    """A recognizer over 72 random views (20 labels), exported as ONNX."""
    g = torch.Generator().manual_seed(0)
    views = torch.rand(72, 1, SIDE, SIDE, generator=g)
    projection = Eigenspace(15).fit(views).to_module(unit_norm=False)
    labels = torch.arange(72) % 20
    recognizer = NearestNeighborRecognizer.from_views(projection, views, labels, torch.arange(72.0) * 5)
    path = folder / "recognizer.onnx"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        export_recognizer(recognizer, path)
    return path


def make_images(folder: Path, count: int) -> list[str]:
    """100 distinct uint8 PNGs, then hard links to them up to ``count`` files."""
    rng = np.random.default_rng(0)
    base = []
    for i in range(min(count, 100)):
        path = folder / f"img{i}.png"
        skimage.io.imsave(path, rng.integers(0, 256, (SIDE, SIDE), dtype=np.uint8), check_contrast=False)
        base.append(path)
    paths = list(base)
    for i in range(len(base), count):
        link = folder / f"img{i}.png"
        os.link(base[i % len(base)], link)
        paths.append(link)
    return [str(p) for p in paths]


def peak_rss_mb(model: Path, images: list[str]) -> float:
    """Runs predict on ``images`` in a child process; returns that child's max RSS in MB."""
    # VmHWM is the high-water mark of this process's own memory map; ru_maxrss would carry
    # the forking parent's peak (torch loaded) across exec.
    script = (
        "import re, sys\n"
        "from torch_eigview.apps.predict import main\n"
        "rc = main(sys.argv[1:])\n"
        "print(re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read()).group(1))\n"
        "sys.exit(rc)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script, "--onnx", str(model), *images],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(out.stdout.strip().splitlines()[-1]) / 1024  # KiB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[100, 1440, 14400])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model = make_model(folder)
        images = make_images(folder, max(args.counts))
        peaks = {n: peak_rss_mb(model, images[:n]) for n in args.counts}
    first = peaks[args.counts[0]]
    print(f"{'images':>8} {'peak RSS (MB)':>14} {'ratio':>7}")
    for n, mb in peaks.items():
        print(f"{n:>8} {mb:14.1f} {mb / first:7.3f}")


if __name__ == "__main__":
    main()
