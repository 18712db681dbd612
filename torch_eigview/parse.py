"""Numbers read from text (a command's arguments, a manifest's cells), strictly.

Python's ``float`` and ``int`` take more than a person means by a number: ``float("1_0")``
is 10 (digit separators), ``float("١٠")`` is 10 (Arabic-Indic digits), and both take
surrounding whitespace. A manifest's azimuth ``1_0`` is far more likely a typo than ten
degrees, so these read decimal notation in ASCII digits only (a sign, digits with an
optional point, an optional exponent), plus ``nan`` and ``inf`` spelled out, which the
callers then refuse by name where a finite number is needed. Nothing here imports torch.
"""

from __future__ import annotations

import re

__all__ = ["parse_float", "parse_int"]

_FLOAT = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?(?:nan|inf|infinity)", re.I)
_INT = re.compile(r"[+-]?[0-9]+")


def parse_float(text: str, name: str) -> float:
    """``text`` as a float, or a ValueError naming ``name`` and the text.

    Example:
        >>> parse_float("-1.5e3", "azimuth"), parse_float("inf", "x")
        (-1500.0, inf)
        >>> parse_float("1_0", "azimuth")
        Traceback (most recent call last):
        ...
        ValueError: azimuth must be a number in decimal digits (such as 10, -2.5 or 1e3), got '1_0'
    """
    if not isinstance(text, str) or not _FLOAT.fullmatch(text):
        raise ValueError(f"{name} must be a number in decimal digits (such as 10, -2.5 or 1e3), got {text!r}")
    return float(text)


def parse_int(text: str, name: str) -> int:
    """``text`` as an int (ASCII digits, an optional sign), or a ValueError naming ``name``.

    Example:
        >>> parse_int("12", "--threads")
        12
    """
    if not isinstance(text, str) or not _INT.fullmatch(text):
        raise ValueError(f"{name} must be an integer in decimal digits, got {text!r}")
    return int(text)
