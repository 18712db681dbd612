"""Peak memory of ``eigview predict`` against the number of images.

A recognizer over random 128×128 gallery views (72 views of 20 labels, k = 15) is
exported as ONNX; 100 distinct PNG images are written, and hard links to them up to the
largest count (each link is a separate file that predict opens and decodes). Then
``eigview predict --onnx`` (``python -m torch_eigview predict``, torch-free) runs in a fresh
process per count, in the order given, and the benchmark reports that process's peak
resident set (``VmHWM``, Linux) and its ratio to the smallest count's peak (the
reference): memory should stay flat in the number of images. Run from the repository root:

``python benchmarks/bench_predict_memory.py [--counts 100 1440 14400] [--quick] [--out FILE]``
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_predict_memory.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import numpy as np
import skimage.io
import torch

from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from torch_eigview import Eigenspace, NearestNeighborRecognizer
from torch_eigview.io import export_recognizer

SIDE = 128
# The command in this interpreter, then its own high-water mark: VmHWM is the peak of this
# process's memory map, where ru_maxrss would carry the forking parent's peak across exec.
_PREDICT = (
    "import re, runpy, sys\n"
    "sys.argv = ['eigview', 'predict', *sys.argv[1:]]\n"
    "try:\n"
    "    runpy.run_module('torch_eigview', run_name='__main__')\n"
    "except SystemExit as exc:\n"
    "    code = exc.code\n"
    "print(re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read()).group(1))\n"
    "sys.exit(code)\n"
)


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


def peak_rss_mib(model: Path, images: list[str]) -> float:
    """Runs predict on ``images`` in a child process; returns that child's peak RSS in MiB."""
    done = subprocess.run(
        [sys.executable, "-c", _PREDICT, "--onnx", str(model), *images],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"eigview predict failed ({done.returncode}): {done.stderr.strip()[-1000:]}")
    return int(done.stdout.strip().splitlines()[-1]) / 1024  # KiB on Linux


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "10 and 100 images (unless --counts says)")
    p.add_argument(
        "--counts", type=int, nargs="+", default=None, help="numbers of images (default 100 1440 14400)"
    )
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    if not sys.platform.startswith("linux"):
        p.error("the peak memory is read from /proc/self/status: Linux only")
    if args.counts is None:
        args.counts = [10, 100] if args.quick else [100, 1440, 14400]
    if min(args.counts) < 1:
        p.error(f"--counts must be >= 1, got {args.counts}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model = make_model(folder)
        images = make_images(folder, max(args.counts))
        peaks = {n: peak_rss_mib(model, images[:n]) for n in args.counts}
    first = peaks[args.counts[0]]
    t = table(
        f"Peak resident memory of eigview predict --onnx on {SIDE}×{SIDE} images, one fresh process per "
        f"count: MiB, ratio to {args.counts[0]} images",
        ["images", "peak MiB", f"× {args.counts[0]} images"],
        [[n, mib, mib / first] for n, mib in peaks.items()],
    )
    print(format_table(t))
    result = {"side": SIDE, "peak_mib": peaks}
    write_record(
        out,
        title="eigview predict: peak memory against the number of images",
        command=command_line(__file__, argv),
        tables=[t],
        raw={"quick": args.quick, **result},
    )
    return result


if __name__ == "__main__":
    main()
