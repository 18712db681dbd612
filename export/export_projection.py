"""Exports the EigenProjection of a saved model to ONNX and checks it in onnxruntime.

Usage::

    eigview coil --root ../shared/data/coil-20-proc --alpha 5 --save model.pt
    python export/export_projection.py --model model.pt --out projection.onnx

The exported graph is the frozen projection only (constants plus Reshape/Sub/MatMul, and
the L2 normalization when the model uses it): images (B, C, H, W) float32 → (B, k), with a
dynamic batch axis. The script compares onnxruntime with eager PyTorch on random images
and prints the largest relative error.
"""

from __future__ import annotations

import argparse

import numpy as np
import onnxruntime
import torch

from torch_eigview import load_recognizer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", required=True, help="file written by eigview coil --save")
    parser.add_argument("--out", required=True, help="ONNX file to write")
    parser.add_argument("--opset", type=int, default=18)
    args = parser.parse_args()

    recognizer, _ = load_recognizer(args.model)
    projection = recognizer.projection.float().eval()
    if projection.image_shape is None:
        raise SystemExit("the model has no image shape; cannot export an image projection")
    sample = torch.rand(2, *projection.image_shape)
    torch.onnx.export(
        projection,
        (sample,),
        args.out,
        dynamo=True,
        dynamic_shapes=({0: torch.export.Dim("batch")},),
        opset_version=args.opset,
    )
    session = onnxruntime.InferenceSession(args.out, providers=["CPUExecutionProvider"])
    name = session.get_inputs()[0].name
    worst = 0.0
    for batch in (1, 7, 32):
        x = torch.rand(batch, *projection.image_shape, generator=torch.Generator().manual_seed(batch))
        (got,) = session.run(None, {name: x.numpy()})
        want = projection(x).detach().numpy()
        worst = max(worst, float(np.abs(got - want).max() / np.abs(want).max()))
    print(f"wrote {args.out}: {projection}; onnxruntime vs eager max relative error {worst:.2e}")


if __name__ == "__main__":
    main()
