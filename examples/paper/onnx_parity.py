"""The closing check: ONNX against eager PyTorch on all 380 COIL-20 test views.

Fits the paper's Fig. 4(b) recognizer (seed views 0° and α, views synthesized over
−20°..20°, 15 components), exports its projection and the whole recognizer, and compares
onnxruntime (CPU) with eager PyTorch on the real views at −45°..45° every 5° of all 20
objects: the largest relative error of the coefficients and the label agreement.

Run: ``python examples/paper/onnx_parity.py [--root DIR] [--alpha 5]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import torch
from record import (
    add_objects_flag,
    add_record_flag,
    add_root_flag,
    check_record,
    coil_folder,
    command_line,
    table,
    write_record,
)

from torch_eigview.evaluation import CoilExperiment
from torch_eigview.io import compare_with_eager, export_projection, export_recognizer
from torch_eigview.scale import threads

TEST_ANGLES = [float(a) for a in range(-45, 50, 5)]


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_root_flag(parser)
    parser.add_argument("--alpha", type=float, default=5.0)
    add_objects_flag(parser)
    add_record_flag(parser, "onnx_parity")
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    folder = coil_folder(parser, args.root)
    warnings.filterwarnings("ignore", category=FutureWarning)
    t0 = time.perf_counter()
    objects = list(args.objects or folder.objects)
    result = CoilExperiment(alpha=args.alpha, objects=objects).run(folder)
    recognizer = result.recognizer
    images = torch.cat([folder.images(obj, TEST_ANGLES) for obj in objects])
    with tempfile.TemporaryDirectory() as tmp:
        export_projection(recognizer.projection, Path(tmp) / "projection.onnx")
        export_recognizer(recognizer, Path(tmp) / "recognizer.onnx")
        coefficients = compare_with_eager(recognizer.projection, Path(tmp) / "projection.onnx", images)
        labels = compare_with_eager(recognizer, Path(tmp) / "recognizer.onnx", images)
    n = images.shape[0]
    agree = round(labels["label_agreement"] * n)
    print(f"COIL-20, alpha={args.alpha:g}: eager accuracy {result.accuracy:.2f}% over {result.n_test} views")
    print(f"coefficients: max relative error onnxruntime vs eager {coefficients['max_rel_err']:.2e}")
    print(f"labels: {agree}/{n} identical; max pose difference {labels['max_pose_diff']:g} deg")
    print(f"max distance difference {labels['max_distance_diff']:.2e}")
    print(f"total {time.perf_counter() - t0:.1f} s")
    out = {**coefficients, **labels, "n": n, "accuracy": result.accuracy}
    write_record(
        args.record,
        title="ONNX against eager PyTorch on the COIL-20 test views",
        command=command_line(__file__, argv),
        tables=[
            table(
                f"The Fig. 4(b) recognizer (α = {args.alpha:g}, k = 15) exported to ONNX and run in onnxruntime "
                f"(CPU) on the {n} real test views of {len(objects)} objects, against eager PyTorch.",
                [
                    "eager accuracy (%)",
                    "views",
                    "coefficients: max relative error",
                    "labels identical",
                    "max pose difference (°)",
                    "max distance difference",
                ],
                [
                    [
                        result.accuracy,
                        n,
                        coefficients["max_rel_err"],
                        f"{agree} / {n}",
                        labels["max_pose_diff"],
                        labels["max_distance_diff"],
                    ]
                ],
            )
        ],
        figures=out,
    )
    return out


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
