"""Exports a saved model's projection (or whole recognizer) to ONNX and checks it in onnxruntime.

Usage::

    eigview coil --root ../shared/data/coil-20-proc --alpha 5 --save model.pt
    python export/export_projection.py --model model.pt --out projection.onnx [--recognizer]

The same as ``eigview export``, plus a check: onnxruntime against eager PyTorch on random
images (batches 1, 7 and 32; the batch axis is dynamic). The graph is
:func:`torch_eigview.io.onnx.export_projection`'s: images (B, C, H, W) float32 → (B, k), or
with ``--recognizer`` → label index, pose, distance; its metadata holds the input size, k,
the label names and the unit-norm flag.
"""

from __future__ import annotations

import argparse

import torch

from torch_eigview import load_recognizer
from torch_eigview.io.onnx import compare_with_eager, export_projection, export_recognizer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", required=True, help="file written by eigview coil --save")
    parser.add_argument("--out", required=True, help="ONNX file to write")
    parser.add_argument("--recognizer", action="store_true", help="export the whole recognizer")
    parser.add_argument("--opset", type=int, default=18)
    args = parser.parse_args()

    recognizer, _ = load_recognizer(args.model)
    model = recognizer if args.recognizer else recognizer.projection
    if args.recognizer:
        info = export_recognizer(recognizer, args.out, opset_version=args.opset)
    else:
        info = export_projection(recognizer.projection, args.out, opset_version=args.opset)
    gen = torch.Generator().manual_seed(0)
    images = torch.cat([torch.rand(b, *info.image_shape, generator=gen) for b in (1, 7, 32)])
    report = compare_with_eager(model, args.out, images)
    print(f"wrote {args.out}: {info}")
    print("onnxruntime vs eager: " + ", ".join(f"{k} {v:.3g}" for k, v in report.items()))


if __name__ == "__main__":
    main()
