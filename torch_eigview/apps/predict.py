"""``eigview predict``: recognition with an exported ONNX model, without torch, or with a model file.

Imports onnxruntime, numpy and scikit-image only (``import torch_eigview`` is lazy), so it
runs where torch is not installed. Images are read as :class:`~torch_eigview.datasets.coil.CoilFolder`
reads them (:mod:`torch_eigview.io.images`: special files refused unopened, float pixels in
[0, 1]) and checked against the shape in the model's metadata, 64 at a time, so memory stays
flat in the number of images; a file that cannot be used, or a row the model answers with a
label index outside its names or a non-finite distance, is reported on stderr and the others
go on (exit status 1 if any failed, 0 otherwise, 2 for a bad model or bad arguments). The
graph is checked before onnxruntime runs it (:mod:`torch_eigview.io.onnx_check`).

A model exported from an ``eigview fit`` model carries its preprocessing in its metadata
(:class:`~torch_eigview.io.preprocessing.Preprocessing`): each image is then converted to
the model's channels and resized to its size (:func:`~torch_eigview.io.preprocessing.prepare_array`)
instead of having to match them, and its background set to 0 unless the model keeps it
(the alpha channel as the mask, else the foreground estimated as ``eigview evaluate`` does). ``--model model.pt`` runs the model file itself with torch
(:class:`~torch_eigview.apps.predict_model.ModelRecognizer`), with the same preprocessing
as ``eigview evaluate``.

Usage::

    eigview predict --onnx model.onnx obj1__0.png obj2__0.png --json predictions.json
    eigview predict --model model.pt photo1.jpg photo2.png
    eigview predict --onnx model.onnx --reject photo.png   # "unknown" for rejected images
    python -m torch_eigview.apps.predict --onnx model.onnx IMAGES...
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from torch_eigview.apps.device_option import DEVICE_HELP, device_arg
from torch_eigview.apps.prediction import Prediction, escape
from torch_eigview.files import check_output_path, write_json
from torch_eigview.io.images import check_regular_file, read_image, to_unit_float
from torch_eigview.io.onnx_check import check_recognizer_graph
from torch_eigview.io.onnx_checksum import verify_checksum
from torch_eigview.io.onnx_metadata import OnnxModelInfo
from torch_eigview.io.preprocessing import prepare_file
from torch_eigview.lazy import require

__all__ = ["OnnxRecognizer", "add_arguments", "main", "read_info", "run"]

_BATCH = 64


class OnnxRecognizer:
    """An exported recognizer in an onnxruntime session (CPU).

    The file is checked before onnxruntime loads it: a regular file (never a FIFO or a
    device), and a graph that :func:`~torch_eigview.io.onnx_check.check_recognizer_graph`
    accepts (operators, inputs and outputs, finite weights, sizes within a budget).

    Args:
        path: a ``.onnx`` file written by ``eigview export --recognizer``.

    Raises:
        ValueError: the file is missing or not a regular file, not an ONNX model, not
            exported by torch_eigview, corrupted (checksum mismatch), a projection rather
            than a recognizer, or a graph that is not a recognizer's.
        ImportError: onnxruntime is not installed (the message names the extra).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        onnxruntime = require("onnxruntime", "onnx", "eigview predict")
        self.path = os.fspath(path)
        check_regular_file(self.path, "ONNX model")
        self.info = read_info(self.path)
        verify_checksum(self.path)  # after read_info, which names a foreign file better
        if self.info.kind != "recognizer":
            raise ValueError(
                f"ONNX model {self.path!r} is a {self.info.kind} (coefficients only); "
                "predict needs a recognizer: export it with 'eigview export --recognizer'"
            )
        if not self.info.label_names:
            raise ValueError(
                f"ONNX model {self.path!r} is a recognizer without label names (damaged metadata)"
            )
        check_recognizer_graph(self.path, self.info)
        try:
            self.session = onnxruntime.InferenceSession(self.path, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own Fail/InvalidProtobuf types
            raise ValueError(f"ONNX model {self.path!r} could not be loaded by onnxruntime: {exc}") from exc
        self.input_name = self.session.get_inputs()[0].name

    def load(self, path: str) -> np.ndarray:
        """Reads one image as (C, H, W) float32 in [0, 1]: preprocessed as the model's metadata
        says, else checked against the model's input size.

        Raises:
            ValueError: not a regular file, unreadable, or (without preprocessing) a shape
                other than the model's (C, H, W).
        """
        prep = self.info.preprocessing
        if prep is not None:
            return prepare_file(path, prep)
        arr = read_image(path)
        if tuple(arr.shape) != self.info.image_shape:
            raise ValueError(
                f"image {path} has shape (C, H, W)={tuple(arr.shape)}, but the model expects "
                f"{self.info.image_shape} (unit_norm={self.info.unit_norm})"
            )
        return to_unit_float(arr, np.float32)

    def predict_rows(self, images: np.ndarray, names: Sequence[str]) -> list[Prediction | str]:
        """Recognizes (B, C, H, W) float32 ``images`` (one onnxruntime call); ``names`` are
        their files. A row whose label index lies outside the model's label names or whose
        pose or distance is not finite comes back as its error message instead."""
        outputs = self.session.run(None, {self.input_name: images})
        index, pose, distance = outputs[:3]
        known = outputs[3] if len(outputs) == 4 else None
        labels = self.info.label_names
        out: list[Prediction | str] = []
        for j, name in enumerate(names):
            i, p, d = int(index[j]), float(pose[j]), float(distance[j])
            if not 0 <= i < len(labels):
                out.append(
                    f"image {name}: the model gave label index {i}, outside its {len(labels)} label names "
                    "(damaged model)"
                )
            elif not (math.isfinite(p) and math.isfinite(d)):
                out.append(
                    f"image {name}: the model gave a non-finite pose {p} or distance {d} (damaged model)"
                )
            else:
                out.append(Prediction(name, labels[i], p, d, None if known is None else bool(known[j])))
        return out

    def predict(self, images: np.ndarray, names: Sequence[str]) -> list[Prediction]:
        """Recognizes (B, C, H, W) float32 ``images`` in batches; ``names`` are their file names.

        Raises:
            ValueError: a row is damaged (see :meth:`predict_rows`).
        """
        out: list[Prediction] = []
        for i in range(0, len(images), _BATCH):
            for row in self.predict_rows(images[i : i + _BATCH], names[i : i + _BATCH]):
                if isinstance(row, str):
                    raise ValueError(row)
                out.append(row)
        return out


def read_info(path: str) -> OnnxModelInfo:
    """The metadata of an ONNX file, read with onnx (the graph, not external weights)."""
    onnx = require("onnx", "onnx", "eigview predict")

    try:
        model = onnx.load(path, load_external_data=False)
    except Exception as exc:  # protobuf DecodeError and others
        onnxruntime = require("onnxruntime", "onnx", "eigview predict")

        try:  # onnxruntime's parser words it best; it refuses what onnx cannot parse
            onnxruntime.InferenceSession(path, providers=["CPUExecutionProvider"])
        except Exception as ort_exc:
            raise ValueError(f"ONNX model {path!r} could not be loaded by onnxruntime: {ort_exc}") from exc
        raise ValueError(f"ONNX model {path!r} could not be loaded by onnx: {exc}") from exc
    # The metadata as the graph recorded it at export: an edited entry is refused.
    return OnnxModelInfo.from_model(model, source=f"ONNX model {path!r}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``eigview predict`` (shared by the CLI and ``python -m``)."""
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--onnx", metavar="FILE", help="model from 'eigview export --recognizer'")
    source.add_argument(
        "--model",
        metavar="FILE",
        help="model file of 'eigview fit' (or 'eigview coil --save'), run with torch",
    )
    parser.add_argument(
        "images", nargs="+", metavar="IMAGE", help="image files, each (C, H, W) like the model's"
    )
    parser.add_argument("--json", metavar="FILE", help="write a list of {image, label, pose, distance}")
    parser.add_argument(
        "--device",
        type=device_arg,
        default=None,
        metavar="DEV",
        help=f"with --model: where the projection and the search run: {DEVICE_HELP} (default cpu; "
        "--onnx runs on onnxruntime's CPU provider)",
    )
    parser.add_argument(
        "--reject",
        action="store_true",
        help="answer 'unknown' for images the model's calibrated rejection takes for unknown objects "
        "(a model fitted with rejection)",
    )
    # For the test that checks this path never imports torch.
    parser.add_argument("--debug-modules", action="store_true", help=argparse.SUPPRESS)


def _batches(model: Any, paths: Sequence[str]) -> Iterator[tuple[np.ndarray, list[str], int]]:
    """Images decoded ``_BATCH`` at a time (memory flat in the number of files): each batch
    as (B, C, H, W) float32, its file names and how many files failed (reported on stderr)."""
    for start in range(0, len(paths), _BATCH):
        good, names, failed = [], [], 0
        for path in paths[start : start + _BATCH]:
            try:
                good.append(model.load(path))
                names.append(path)
            except ValueError as exc:
                print(f"eigview predict: error: {escape(str(exc))}", file=sys.stderr)
                failed += 1
        yield (np.stack(good) if good else np.empty((0, *model.info.image_shape), np.float32)), names, failed


def run(args: argparse.Namespace) -> int:
    """Runs ``eigview predict`` on parsed arguments; returns the exit status.

    Images are read, recognized and printed one batch at a time. Names from files (label
    names, image paths) are printed escaped (:func:`escape`).

    Raises:
        ValueError: the model cannot be used (the caller reports it, exit status 2).
    """
    if args.json:  # before any image is read: a bad path must not cost the run
        inputs = [("--onnx", args.onnx), ("--model", args.model), *(("IMAGE", path) for path in args.images)]
        check_output_path(args.json, "--json", inputs=inputs)
    model: Any
    if args.model is not None:
        from torch_eigview.apps.predict_model import ModelRecognizer  # imports torch

        model = ModelRecognizer(args.model, device="cpu" if args.device is None else args.device)
    else:
        if args.device is not None:
            raise ValueError(
                f"--device {args.device} applies to --model only: --onnx runs on onnxruntime's CPU provider"
            )
        model = OnnxRecognizer(args.onnx)
    if args.reject and not model.info.reject:
        raise ValueError(
            f"--reject needs a model with rejection thresholds (for ONNX a 'known' output); model "
            f"{args.model or args.onnx!r} has none: fit it with rejection calibrated (and export it again)"
        )
    predictions: list[Prediction] = []
    n_failed = 0
    for images, names, failed in _batches(model, args.images):
        n_failed += failed
        for row in model.predict_rows(images, names) if names else []:
            if isinstance(row, str):
                print(f"eigview predict: error: {escape(row)}", file=sys.stderr)
                n_failed += 1
                continue
            if args.json:  # held for the file only: memory stays flat without it
                predictions.append(row)
            label = "unknown" if args.reject and row.known is False else f"label {escape(row.label)}"
            print(f"{escape(row.image)}\t{label}\tpose {row.pose:g}\tdistance {row.distance:.6g}")
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
