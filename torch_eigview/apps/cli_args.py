"""The ``eigview`` command's argument types and shared options.

Each type names the flag the user typed in its error (never an internal variable), and
imports torch only where it must, so that ``eigview predict`` stays torch-free.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable, Iterable
from functools import partial
from typing import TypeVar

from torch_eigview.parse import parse_float, parse_int

__all__ = [
    "MIN_OPSET",
    "ArgumentParser",
    "HelpFormatter",
    "add_kernel_arguments",
    "add_quiet",
    "add_threads",
    "angle_arg",
    "bounded_int_arg",
    "components_arg",
    "elevation_arg",
    "finite_arg",
    "gamma_arg",
    "objects_arg",
    "opset_arg",
    "pose_step_arg",
    "progress_bar",
    "threads_arg",
    "word_or_float",
]

T = TypeVar("T")

MIN_OPSET = 18  # what torch_eigview.io.onnx exports


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser, reading every number argparse's own test misses as a value.

    argparse tells a negative number from an option with ``-\\d+$|-\\d*\\.\\d+$``, so
    ``--test -1e300 1e300`` takes ``-1e300`` for an unknown option and says "expected 2
    arguments"; with exponents (and ``-inf``/``-nan``, refused later by name as not finite)
    in the pattern, the value reaches the option's own check. No option here looks like a
    number, so nothing is shadowed. Sub-commands inherit the class.
    """

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._negative_number_matcher = re.compile(
            r"^-(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?$|^-(?:inf|infinity|nan)$", re.I
        )


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Every option's help ends with its default, where it has one to show (not a flag
    that is off, not an option that is unset by default); descriptions keep their lines."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        shown = default not in (None, False, argparse.SUPPRESS) and "%(default)" not in text
        if not action.option_strings or not shown or action.help == argparse.SUPPRESS:
            return action.help
        if isinstance(default, (list, tuple)):
            return (
                f"{text} (default: {' '.join(f'{v:g}' if isinstance(v, float) else str(v) for v in default)})"
            )
        if isinstance(default, float):
            return f"{text} (default: {default:g})"
        return f"{text} (default: %(default)s)"


def components_arg(text: str) -> int | float:
    try:
        value = parse_float(text, "--components")
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--components must be an int or a fraction in (0, 1), got {text!r}"
        ) from None
    if value.is_integer() and value >= 1:
        return int(value)
    if 0 < value < 1:
        return value
    raise argparse.ArgumentTypeError(
        f"--components must be an int >= 1 or a fraction in (0, 1), got {text!r}"
    )


def word_or_float(text: str, word: str, message: str) -> float | str:
    """``word`` itself, or ``text`` as a finite float; ``message`` is the argparse error otherwise."""
    if text == word:
        return text
    try:
        value = parse_float(text, word)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(message)
    return value


def finite_arg(flag: str) -> Callable[[str], float]:
    """An argparse type: a finite number, the error naming ``flag`` (never an internal name)."""

    def parse(text: str) -> float:
        try:
            value = parse_float(text, flag)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{flag} must be a finite number, got {text!r}")
        return value

    return parse


def angle_arg(flag: str) -> Callable[[str], float]:
    """An argparse type: degrees within [-360, 360], the error naming ``flag``.

    No angle of the method (a seed's azimuth, a range from it, a step) means anything past
    a full turn, and ``--center 1e300`` would otherwise run, every pose wrapping to noise.
    """
    finite = finite_arg(flag)

    def parse(text: str) -> float:
        value = finite(text)
        if abs(value) > 360.0:
            raise argparse.ArgumentTypeError(f"{flag} must be degrees within [-360, 360], got {text!r}")
        return value

    return parse


def pose_step_arg(text: str) -> float:
    """``--pose-step DEG``: degrees between pose indices, a number in (0, 360] (argparse type)."""
    value = finite_arg("--pose-step")(text)
    if not 0 < value <= 360:
        raise argparse.ArgumentTypeError(f"--pose-step must be a number of degrees in (0, 360], got {text!r}")
    return value


def bounded_int_arg(flag: str, minimum: int, limit: str | None = None) -> Callable[[str], int]:
    """An argparse type: an int >= ``minimum`` and at most the :mod:`torch_eigview.config`
    limit named ``limit``, the error naming ``flag``."""

    def parse(text: str) -> int:
        try:
            value = parse_int(text, flag)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} must be an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{flag}={value} must be >= {minimum}")
        if limit is not None:
            from torch_eigview.config import check_limit

            try:
                check_limit(value, flag, "pixels per image side", limit)
            except ValueError as exc:
                raise argparse.ArgumentTypeError(str(exc)) from None
        return value

    return parse


def opset_arg(text: str) -> int:
    import onnx

    newest = onnx.defs.onnx_opset_version()
    value = bounded_int_arg("--opset", MIN_OPSET)(text)
    if value > newest:
        # The exporter would silently write another opset than the one asked for.
        raise argparse.ArgumentTypeError(
            f"--opset={value} must be at most {newest}, the newest opset of the installed onnx {onnx.__version__}"
        )
    return value


def elevation_arg(text: str) -> float | str:
    return word_or_float(
        text, "auto", f"--elevation must be 'auto' or a finite number of degrees, got {text!r}"
    )


def objects_arg(text: str) -> list[int]:
    from torch_eigview.datasets.coil import parse_object_spec

    try:
        return parse_object_spec(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def gamma_arg(text: str) -> float | str:
    return word_or_float(text, "median", f"--gamma must be a number > 0 or 'median', got {text!r}")


def add_kernel_arguments(parser: argparse.ArgumentParser) -> None:
    """``--kernel`` and ``--gamma``, as ``eigview coil`` and ``eigview fit`` take them."""
    parser.add_argument(
        "--kernel",
        choices=("rbf", "poly", "cosine", "linear"),
        default=None,
        help="kernel PCA instead of the linear eigenspace",
    )
    parser.add_argument(
        "--gamma",
        type=gamma_arg,
        default=None,
        help="with --kernel rbf or poly: the kernel's gamma > 0, or 'median' (rbf: 1/median squared "
        "distance); 1/N by default",
    )


def add_quiet(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--quiet", action="store_true", help="no progress bar (there is none when stderr is not a terminal)"
    )


def _int_at_least(text: str, minimum: int) -> int | None:
    """``text`` as an int >= ``minimum``, or None."""
    try:
        value = parse_int(text, "")
    except ValueError:
        return None
    return value if value >= minimum else None


def threads_arg(text: str) -> int:
    """``--threads N``: an int >= 1 (argparse type)."""
    value = _int_at_least(text, 1)
    if value is None:
        raise argparse.ArgumentTypeError(f"--threads must be an integer >= 1, got {text!r}")
    return value


def workers_arg(text: str) -> int | str:
    """``--workers N|auto``: an int >= 0, or ``auto`` (argparse type)."""
    value = "auto" if text == "auto" else _int_at_least(text, 0)
    if value is None:
        raise argparse.ArgumentTypeError(f"--workers must be 'auto' or an integer >= 0, got {text!r}")
    return value


def add_threads(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--threads",
        type=threads_arg,
        default=None,
        metavar="N",
        help="torch intra-op threads; by default 1, since a second thread gains little here and spins "
        "when another process keeps the cores busy, and a large eigen step takes the CPUs other "
        "processes leave idle",
    )


def progress_bar(quiet: bool, desc: str, unit: str) -> Callable[[Iterable[T]], Iterable[T]] | None:
    """A tqdm wrapper for a command's main loop, or None when ``quiet`` or stderr is no terminal.

    The bar goes to stderr, so it shows whenever a person watches the command, even with
    stdout redirected to a file; a log or a pipe (stderr not a TTY) gets no bar.
    ``leave=False``: the bar disappears when done, and the results print below it alone.
    """
    if quiet or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return partial(tqdm, desc=desc, unit=unit, leave=False, file=sys.stderr)
