"""``--device`` of ``eigview fit``, ``evaluate`` and ``predict --model``: where the tensors work.

The option's text is checked by argparse without importing torch (``eigview predict
--onnx`` never imports it); whether the device exists is checked when the command runs,
before any image is read. ``fit`` moves the seed views there, and the estimator follows
them (synthesis and the eigenspace run on that device); ``evaluate`` and ``predict``
move the model's recognizer there and each batch of views with it. The model file is
written and read on the CPU whatever the device.
"""

from __future__ import annotations

import argparse
import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

__all__ = ["DEVICE_HELP", "add_device_argument", "device_arg", "resolve_device"]

_PATTERN = re.compile(r"^(?:auto|cpu|cuda(?::[0-9]+)?)$")
DEVICE_HELP = "cpu, cuda, cuda:N (the N-th GPU) or auto (cuda when a GPU is available, else cpu)"


def device_arg(text: str) -> str:
    """An argparse type: ``cpu``, ``cuda``, ``cuda:N`` or ``auto``, the error naming ``--device``."""
    value = text.strip().lower()
    if not _PATTERN.match(value):
        raise argparse.ArgumentTypeError(f"--device must be {DEVICE_HELP}; got {text!r}")
    return value


def add_device_argument(parser: argparse.ArgumentParser, work: str) -> None:
    """``--device DEV`` (default cpu); ``work`` says what runs there, for the help ("the
    search runs")."""
    parser.add_argument(
        "--device",
        type=device_arg,
        default="cpu",
        metavar="DEV",
        help=f"where {work}: {DEVICE_HELP}",
    )


def resolve_device(value: str) -> torch.device:
    """The torch device a checked ``--device`` names.

    Raises:
        ValueError: ``cuda`` (or ``cuda:N``) without a CUDA device, or N past the last
            one; the message names ``--device`` and the remedy.
    """
    import torch

    if value == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(value)
    if device.type != "cuda":
        return device
    if not torch.cuda.is_available():
        raise ValueError(f"--device {value}: no CUDA device is available; use --device cpu")
    count = torch.cuda.device_count()
    if device.index is not None and device.index >= count:
        raise ValueError(
            f"--device {value}: there are {count} CUDA device(s), cuda:0 to cuda:{count - 1}; "
            "use one of them, or --device cpu"
        )
    return device
