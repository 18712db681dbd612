"""The options ``eigview fit``, ``evaluate`` and ``coil`` share: where the views are, and
what their background is.

A command's views come from a CSV manifest (``--manifest``) or a folder pattern
(``--pattern`` under ``--root``), read by :class:`~torch_eigview.datasets.manifest.ViewManifest`;
``--background`` and ``--tolerance`` give the background rule that
:func:`~torch_eigview.datasets.background_rule` turns into a
:class:`~torch_eigview.datasets.background.BackgroundModel`.
"""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING, Any

from torch_eigview.apps.cli_args import finite_arg
from torch_eigview.parse import parse_float

if TYPE_CHECKING:
    from torch_eigview.datasets.manifest import ViewManifest

__all__ = [
    "add_background_arguments",
    "add_manifest_arguments",
    "background_arg",
    "background_fields",
    "check_not_views",
    "load_manifest",
    "manifest_inputs",
    "resolve_background",
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


def background_arg(text: str) -> str | tuple[float, ...]:
    """``--background``: ``keep``, ``auto``, or a colour ``R,G,B`` (or one gray value) in 0-255,
    returned in [0, 1]."""
    if text in ("keep", "auto"):
        return text
    parts = text.split(",")
    try:
        values = [parse_float(p.strip(), "--background") for p in parts]
    except ValueError:
        values = []
    if len(values) not in (1, 3) or not all(math.isfinite(v) and 0.0 <= v <= 255.0 for v in values):
        raise argparse.ArgumentTypeError(
            f"--background {text!r} must be keep, auto, or a colour R,G,B (or one gray value) of numbers "
            "in 0-255, e.g. 26,77,179"
        )
    return tuple(v / 255.0 for v in values)


def _tolerance_arg(text: str) -> float:
    value = finite_arg("--tolerance")(text)
    if not 0.0 < value <= 255.0 * math.sqrt(3.0):
        raise argparse.ArgumentTypeError(f"--tolerance {text!r} must be a number in (0, 441.7] (0-255 scale)")
    return value


_AUTO_HELP = (
    "auto: each view's mask (manifest mask column, alpha channel) where given, else the foreground "
    "estimated from the border's colours"
)


def add_background_arguments(
    parser: argparse.ArgumentParser, auto: str = _AUTO_HELP, default: str | None = "keep"
) -> None:
    """``--background keep|auto|R,G,B`` and ``--tolerance T`` (both on the 0-255 scale);
    ``auto`` the help's words for ``--background auto``; ``default`` None: the rule follows
    the masks given (:func:`resolve_background`)."""
    chosen = (
        ""
        if default is not None
        else " By default auto where the views come with masks (a mask column, an alpha channel), else keep"
    )
    parser.add_argument(
        "--background",
        type=background_arg,
        default=default,
        metavar="keep|auto|R,G,B",
        help=f"keep: pixels as read (black-background data); {auto}; "
        f"R,G,B: that background colour, 0-255. Except with keep the background is set to 0.{chosen}",
    )
    parser.add_argument(
        "--tolerance",
        type=_tolerance_arg,
        default=None,
        metavar="T",
        help="with auto or R,G,B: the largest colour distance (Euclidean, 0-255 scale) that is still "
        "background (default: from the spread of the border's colours)",
    )


def background_fields(args: argparse.Namespace) -> dict[str, Any]:
    """The :class:`~torch_eigview.io.preprocessing.Preprocessing` fields of ``--background``
    and ``--tolerance``.

    Raises:
        ValueError: ``--tolerance`` with ``--background keep``.
    """
    choice = args.background
    if args.tolerance is not None and choice in ("keep", None):
        raise ValueError("--tolerance goes with --background auto or R,G,B, not with keep")
    tolerance = None if args.tolerance is None else args.tolerance / 255.0
    if isinstance(choice, tuple):
        return {"background": "colour", "colour": choice, "tolerance": tolerance}
    return {"background": choice, "colour": None, "tolerance": tolerance}


def resolve_background(args: argparse.Namespace, has_masks: bool, has_alpha: bool) -> str:
    """Sets ``args.background`` where it was left to the default: ``auto`` when the views
    come with masks (the manifest's mask column, an alpha channel), else ``keep``; returns
    the rule and why, for the command to say."""
    if args.background is not None:
        return "as given"
    if has_masks or has_alpha:
        args.background = "auto"
        return "the manifest lists masks" if has_masks else "the images have an alpha channel"
    args.background = "keep"
    return "no masks given"


def manifest_inputs(args: argparse.Namespace) -> list[tuple[str, str | None]]:
    """The input files of the manifest options (an output must not overwrite one)."""
    return [("--manifest", args.manifest), ("--root", args.root)]


def check_not_views(outputs: list[tuple[str, str | None]], manifest: ViewManifest) -> None:
    """Refuses an output that is one of the manifest's image or mask files (before any work:
    :func:`~torch_eigview.files.check_outputs` knows only the manifest itself).

    Raises:
        ValueError: naming the flag, the file and the manifest line that lists it.
    """
    import os

    given = [(flag, os.path.realpath(path)) for flag, path in outputs if path]
    given = [(flag, target) for flag, target in given if os.path.exists(target)]  # a new file is no input
    for entry in manifest if given else ():
        for what, file in (("image", entry.path), ("mask", entry.mask)):
            for flag, target in given:
                if file is not None and os.path.realpath(file) == target:
                    raise ValueError(
                        f"{flag}={target!r} is the {what} of {entry.source}: writing it would destroy an "
                        "input; give another output path"
                    )


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
