"""``eigview predict``: recognition with an exported ONNX model, without torch.

Imports onnxruntime, numpy and scikit-image only (``import torch_eigview`` is lazy), so it
runs where torch is not installed. Images are read as :class:`~torch_eigview.datasets.coil.CoilFolder`
reads them (:mod:`torch_eigview.io.images`) and checked against the shape in the model's
metadata; a file that cannot be used is reported on stderr and the others go on (exit
status 1 if any failed, 0 otherwise, 2 for a bad model or bad arguments).

Usage::

    eigview predict --onnx model.onnx obj1__0.png obj2__0.png --json predictions.json
    python -m torch_eigview.apps.predict --onnx model.onnx IMAGES...
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from torch_eigview.files import check_output_path, write_json
from torch_eigview.io.images import read_image, to_unit_float
from torch_eigview.io.onnx_checksum import verify_checksum
from torch_eigview.io.onnx_metadata import OnnxModelInfo
from torch_eigview.lazy import require

__all__ = ["OnnxRecognizer", "Prediction", "add_arguments", "main", "run"]

_BATCH = 64


@dataclass(frozen=True)
class Prediction:
    """One recognized image: its file, label name, pose (degrees) and eigenspace distance."""

    image: str
    label: str
    pose: float
    distance: float

    def to_json(self) -> dict[str, Any]:
        return {"image": self.image, "label": self.label, "pose": self.pose, "distance": self.distance}


class OnnxRecognizer:
    """An exported recognizer in an onnxruntime session (CPU).

    Args:
        path: a ``.onnx`` file written by ``eigview export --recognizer``.

    Raises:
        ValueError: the file is missing, not an ONNX model, not exported by torch_eigview,
            corrupted (checksum mismatch), or a projection rather than a recognizer.
        ImportError: onnxruntime is not installed (the message names the extra).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        onnxruntime = require("onnxruntime", "onnx", "eigview predict")
        self.path = os.fspath(path)
        if not os.path.isfile(self.path):
            raise ValueError(f"ONNX model {self.path!r} does not exist or is not a file")
        try:
            self.session = onnxruntime.InferenceSession(self.path, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own Fail/InvalidProtobuf types
            raise ValueError(f"ONNX model {self.path!r} could not be loaded by onnxruntime: {exc}") from exc
        props = self.session.get_modelmeta().custom_metadata_map
        self.info = OnnxModelInfo.from_props(props, source=f"ONNX model {self.path!r}")
        verify_checksum(self.path)  # after the two checks above, which name a foreign file better
        if self.info.kind != "recognizer":
            raise ValueError(
                f"ONNX model {self.path!r} is a {self.info.kind} (coefficients only); "
                "predict needs a recognizer: export it with 'eigview export --recognizer'"
            )
        self.input_name = self.session.get_inputs()[0].name

    def load(self, path: str) -> np.ndarray:
        """Reads one image as (C, H, W) float32 in [0, 1], checked against the model's input size.

        Raises:
            ValueError: unreadable file, or a shape other than the model's (C, H, W).
        """
        arr = read_image(path)
        if tuple(arr.shape) != self.info.image_shape:
            raise ValueError(
                f"image {path} has shape (C, H, W)={tuple(arr.shape)}, but the model expects "
                f"{self.info.image_shape} (unit_norm={self.info.unit_norm})"
            )
        return to_unit_float(arr, np.float32)

    def predict(self, images: np.ndarray, names: Sequence[str]) -> list[Prediction]:
        """Recognizes (B, C, H, W) float32 ``images``; ``names`` are their file names."""
        out: list[Prediction] = []
        for i in range(0, len(images), _BATCH):
            index, pose, distance = self.session.run(None, {self.input_name: images[i : i + _BATCH]})
            for j in range(len(index)):
                out.append(
                    Prediction(
                        names[i + j],
                        self.info.label_names[int(index[j])],
                        float(pose[j]),
                        float(distance[j]),
                    )
                )
        return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``eigview predict`` (shared by the CLI and ``python -m``)."""
    parser.add_argument(
        "--onnx", required=True, metavar="FILE", help="model from 'eigview export --recognizer'"
    )
    parser.add_argument(
        "images", nargs="+", metavar="IMAGE", help="image files, each (C, H, W) like the model's"
    )
    parser.add_argument("--json", metavar="FILE", help="write a list of {image, label, pose, distance}")
    # For the test that checks this path never imports torch.
    parser.add_argument("--debug-modules", action="store_true", help=argparse.SUPPRESS)


def run(args: argparse.Namespace) -> int:
    """Runs ``eigview predict`` on parsed arguments; returns the exit status.

    Raises:
        ValueError: the model cannot be used (the caller reports it, exit status 2).
    """
    if args.json:  # before any image is read: a bad path must not cost the run
        inputs = [("--onnx", args.onnx), *(("IMAGE", path) for path in args.images)]
        check_output_path(args.json, "--json", inputs=inputs)
    model = OnnxRecognizer(args.onnx)
    good: list[np.ndarray] = []
    names: list[str] = []
    n_failed = 0
    for path in args.images:
        try:
            good.append(model.load(path))
            names.append(path)
        except ValueError as exc:
            print(f"eigview predict: error: {exc}", file=sys.stderr)
            n_failed += 1
    predictions = model.predict(np.stack(good), names) if good else []
    for p in predictions:
        print(f"{p.image}\tlabel {p.label}\tpose {p.pose:g}\tdistance {p.distance:.6g}")
    if args.json:
        write_json(args.json, [p.to_json() for p in predictions])
    if n_failed:
        print(f"eigview predict: {n_failed} of {len(args.images)} images failed", file=sys.stderr)
    if args.debug_modules:
        print(f"torch imported: {'torch' in sys.modules}", file=sys.stderr)
    return 1 if n_failed else 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m torch_eigview.apps.predict``: the same as ``eigview predict``."""
    parser = argparse.ArgumentParser(prog="eigview predict", description=__doc__.splitlines()[0])
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run(args)
    except (ValueError, ImportError) as exc:  # a missing extra's message names the pip install
        parser.exit(2, f"eigview predict: error: {exc}\n")


if __name__ == "__main__":
    sys.exit(main())
