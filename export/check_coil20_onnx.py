"""The closing check: ONNX against eager PyTorch on all 380 COIL-20 test views.

Fits the paper's Fig. 4(b) recognizer (seed views 0° and α, views synthesized over
−20°..20°, 15 components), exports its projection and the whole recognizer, and compares
onnxruntime (CPU) with eager PyTorch on the real views at −45°..45° every 5° of all 20
objects: the largest relative error of the coefficients and the label agreement.

Run: ``python export/check_coil20_onnx.py [--root ../shared/data/coil-20-proc] [--alpha 5]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import torch

from torch_eigview import CoilFolder
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.io.onnx import compare_with_eager, export_projection, export_recognizer

DEFAULT_ROOT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "coil-20-proc"
TEST_ANGLES = [float(a) for a in range(-45, 50, 5)]


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=DEFAULT_ROOT)
    parser.add_argument("--alpha", type=float, default=5.0)
    args = parser.parse_args(argv)
    warnings.filterwarnings("ignore", category=FutureWarning)
    t0 = time.perf_counter()
    folder = CoilFolder(args.root)
    result = CoilExperiment(alpha=args.alpha).run(folder)
    recognizer = result.recognizer
    images = torch.cat([folder.images(obj, TEST_ANGLES) for obj in folder.objects])
    with tempfile.TemporaryDirectory() as tmp:
        export_projection(recognizer.projection, Path(tmp) / "projection.onnx")
        export_recognizer(recognizer, Path(tmp) / "recognizer.onnx")
        coefficients = compare_with_eager(Path(tmp) / "projection.onnx", recognizer.projection, images)
        labels = compare_with_eager(Path(tmp) / "recognizer.onnx", recognizer, images)
    n = images.shape[0]
    agree = round(labels["label_agreement"] * n)
    print(f"COIL-20, alpha={args.alpha:g}: eager accuracy {result.accuracy:.2f}% over {result.n_test} views")
    print(f"coefficients: max relative error onnxruntime vs eager {coefficients['max_rel_err']:.2e}")
    print(f"labels: {agree}/{n} identical; max pose difference {labels['max_pose_diff']:g} deg")
    print(f"max distance difference {labels['max_distance_diff']:.2e}")
    print(f"total {time.perf_counter() - t0:.1f} s")
    return {**coefficients, **labels, "n": n}


if __name__ == "__main__":
    main()
