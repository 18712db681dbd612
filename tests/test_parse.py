"""Strict number parsing (issue 41, class 1): what ``float`` and ``int`` accept beyond
decimal notation is refused by name; decimal notation reads as ``float`` reads it."""

from __future__ import annotations

import math

import pytest

from torch_eigview.parse import parse_float, parse_int


@pytest.mark.parametrize("text", ["10", "-2.5", "+3.", ".5", "1e3", "-1E-300", "1e300", "0", "007"])
def test_decimal_floats_read_as_float_reads_them(text: str) -> None:
    assert parse_float(text, "x") == float(text)


@pytest.mark.parametrize("text", ["nan", "inf", "-Infinity", "NaN"])
def test_spelled_out_non_finite(text: str) -> None:
    value = parse_float(text, "x")
    assert math.isnan(value) or math.isinf(value)


@pytest.mark.parametrize(
    "text",
    ["1_0", "١٠", "１０", " 10", "10 ", "", "1e", "e3", "--1", "1.2.3", "0x10", "10deg", "1,5", "∞"],
)
def test_other_spellings_are_refused_by_name(text: str) -> None:
    float_ok = True
    try:
        float(text)
    except ValueError:
        float_ok = False
    with pytest.raises(ValueError, match=r"azimuth must be a number in decimal digits .*got "):
        parse_float(text, "azimuth")
    if text in ("1_0", "١٠", "１０"):
        assert float_ok  # the cases Python's float would have read as ten


@pytest.mark.parametrize("text", ["1_0", "١٠", "1.0", " 1", "", "+", "1e3"])
def test_ints_refused_by_name(text: str) -> None:
    with pytest.raises(ValueError, match=r"--threads must be an integer in decimal digits, got "):
        parse_int(text, "--threads")
    assert parse_int("-12", "n") == -12 and parse_int("+3", "n") == 3


def test_not_a_string() -> None:
    with pytest.raises(ValueError, match="x must be a number"):
        parse_float(10, "x")  # type: ignore[arg-type]
