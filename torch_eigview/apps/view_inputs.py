"""What ``eigview fit``, ``evaluate`` and ``predict`` share: the manifest options, the model file.

A command's views come from a CSV manifest (``--manifest``) or a folder pattern
(``--pattern`` under ``--root``), read by :class:`~torch_eigview.datasets.manifest.ViewManifest`;
a model file is :func:`~torch_eigview.io.checkpoint.save_recognizer`'s, with the
:class:`~torch_eigview.io.preprocessing.Preprocessing` that ``eigview fit`` recorded.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from torch_eigview.io.preprocessing import Preprocessing

if TYPE_CHECKING:
    from torch_eigview.datasets.manifest import ViewManifest
    from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = [
    "add_manifest_arguments",
    "label_table",
    "load_manifest",
    "load_model",
    "manifest_inputs",
    "model_preprocessing",
]


def add_manifest_arguments(parser: argparse.ArgumentParser) -> None:
    """``--manifest FILE`` or ``--pattern P --root DIR``."""
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument(
        "--manifest", metavar="FILE", help="CSV with the columns path,object,azimuth[,elevation][,mask]"
    )
    group.add_argument(
        "--pattern",
        metavar="P",
        help='file names under --root, e.g. "{object}/{object}-{elevation}-{azimuth}.png"',
    )
    parser.add_argument("--root", metavar="DIR", help="the folder --pattern searches")


def manifest_inputs(args: argparse.Namespace) -> list[tuple[str, str | None]]:
    """The input files of the manifest options (an output must not overwrite one)."""
    return [("--manifest", args.manifest), ("--root", args.root)]


def load_manifest(args: argparse.Namespace, skipped: list[str] | None = None) -> ViewManifest:
    """The manifest the options name; with ``skipped``, bad CSV lines are collected there and left out.

    Raises:
        ValueError: ``--pattern`` without ``--root`` (or ``--root`` without it), or a bad
            manifest (the message names the file and the line).
    """
    from torch_eigview.datasets.manifest import ViewManifest

    if args.pattern is not None:
        if args.root is None:
            raise ValueError(f"--pattern {args.pattern!r} needs --root, the folder it searches")
        return ViewManifest.from_pattern(args.root, args.pattern)
    if args.root is not None:
        raise ValueError(f"--root {args.root!r} goes with --pattern, not with --manifest")
    return ViewManifest.from_csv(args.manifest, skipped=skipped)


def model_preprocessing(
    recognizer: NearestNeighborRecognizer, meta: dict[str, Any], source: str
) -> Preprocessing:
    """The preprocessing ``eigview fit`` recorded in a model's metadata.

    A model without one (``eigview coil --save``) takes images of its own (C, H, W) as
    read, with the black background of the data it came from.
    """
    if "preprocessing" in meta:
        prep = Preprocessing.from_json(meta["preprocessing"], source)
        shape = recognizer.projection.image_shape
        if shape is not None and prep.image_shape != tuple(shape):
            raise ValueError(
                f"{source}: its preprocessing gives {prep.image_shape}, its eigenspace takes {shape}"
            )
        return prep
    shape = recognizer.projection.image_shape
    if shape is None or shape[0] not in (1, 3):
        raise ValueError(
            f"{source} records no preprocessing and takes images {shape}: write it with eigview fit"
        )
    return Preprocessing((shape[1], shape[2]), shape[0], unit_norm=bool(recognizer.projection.unit_norm))


def label_table(recognizer: NearestNeighborRecognizer) -> dict[str, int]:
    """Object name -> label value: the recognizer's label names (one per distinct label, in
    sorted label order), or each label's own number (``eigview coil --save``: COIL ids)."""
    distinct = sorted(set(recognizer.labels.tolist()))
    names = recognizer.label_names or [str(label) for label in distinct]
    return dict(zip(names, distinct, strict=True))


def load_model(path: str) -> tuple[NearestNeighborRecognizer, dict[str, Any], Preprocessing]:
    """A model file's recognizer (checksum verified), metadata and preprocessing."""
    from torch_eigview.io.checkpoint import load_recognizer

    recognizer, meta = load_recognizer(path)
    return recognizer, meta, model_preprocessing(recognizer, meta, f"model {path}")
