"""Bad input to ``eigview coil`` and ``demo``: each must end in exit
status 2 and a message that names the flag or file, the constraint and the value (the
commands' files, models, images and outputs, are in test_cli_files.py). Good command lines
(``GOOD``: ``--threads 1``, a fraction of components) must run and give a sane answer.

The cases are the ones found missing from ``tests/apps`` and ``tests/test_faults.py``; each
is judged by :func:`tests.adversarial.harness.outcome`.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import skimage.io

from tests.adversarial import files
from tests.adversarial.harness import (
    COMPONENTS,
    EMPTY,
    NOT_AN_IMAGE,
    Case,
    Good,
    Ran,
    command,
    judge,
    outcome,
    params,
    threads_error,
)

A = ("--alpha", "10")


def _coil_with(extra: str, make: object) -> object:
    """A COIL folder plus one bad entry named ``extra``, made by ``make(path)``."""

    def setup(tmp: Path) -> None:
        files.coil(tmp)
        make(tmp / extra)  # type: ignore[operator]

    return setup


def _coil_sizes(tmp: Path) -> None:
    files.coil(tmp)
    skimage.io.imsave(tmp / "obj2__0.png", np.zeros((16, 16), dtype=np.uint8), check_contrast=False)


def _empty_dir(tmp: Path) -> None:
    (tmp / "empty").mkdir()


def _coil(id: str, *flags: str, match: str, setup: object = files.coil) -> Case:
    """``eigview coil --folder {tmp} FLAGS`` on a COIL folder made by ``setup``."""
    return Case(id, command("coil", "--folder", "{tmp}", *flags, setup=setup), match)  # type: ignore[arg-type]


COIL = [
    Case(
        "root-missing",
        command("coil", "--folder", "{tmp}/nope", *A),
        r"nope'? \(given as the folder itself\) must be an existing directory",
    ),
    Case(
        "root-is-a-file",
        command("coil", "--folder", "{tmp}/f.txt", *A, setup=lambda t: files.text(t / "f.txt")),
        r"f\.txt'? \(given as the folder itself\) must be an existing directory",
    ),
    Case(
        "root-empty",
        command("coil", "--folder", "{tmp}/empty", *A, setup=_empty_dir),
        r"empty'? holds no COIL files \(obj\{O\}__\{P\}\.png\)",
    ),
    _coil("components-0", *A, "--components", "0", match=COMPONENTS.format("0")),
    _coil("components-negative", *A, "--components", "-3", match=COMPONENTS.format("-3")),
    _coil("components-1.5", *A, "--components", "1.5", match=COMPONENTS.format(r"1\.5")),
    _coil("components-nan", *A, "--components", "nan", match=COMPONENTS.format("nan")),
    _coil(
        "gamma-negative",
        *A,
        "--kernel",
        "rbf",
        "--gamma",
        "-1",
        match=r"gamma=-1\.0 must be a finite number > 0",
    ),
    _coil("gamma-without-kernel", *A, "--gamma", "0.5", match=r"gamma=0\.5 needs a kernel"),
    _coil("circle-0", "--circle", "0", match=r"--circle=0 must be >= 2"),
    _coil("circle-1", "--circle", "1", match=r"--circle=1 must be >= 2"),
    _coil(
        "test-reversed",
        *A,
        "--test",
        "10",
        "-10",
        match=r"test must have start <= stop, got start=10\.0, stop=-10\.0",
    ),
    _coil(
        "synth-reversed",
        *A,
        "--synth",
        "20",
        "-20",
        "1",
        match=r"synth must have start <= stop, got start=20\.0, stop=-20\.0",
    ),
    _coil("synth-step-0", *A, "--synth", "-20", "20", "0", match=r"synth step must be positive, got 0\.0"),
    _coil(
        "elevation-95",
        *A,
        "--elevation",
        "95",
        match=r"elevation=95\.0 must be an angle in degrees in \(-90, 90\)",
    ),
    _coil(
        "elevation-nan",
        *A,
        "--elevation",
        "nan",
        match=r"--elevation must be .auto. or a finite number of degrees, got .nan.",
    ),
    _coil("objects-0", *A, "--objects", "0", match=r"--objects: .*must hold positive object ids, got 0"),
    _coil("objects-reversed", *A, "--objects", "5-3", match=r"--objects: .*holds the reversed range 5-3"),
    _coil("objects-text", *A, "--objects", "abc", match=r"--objects: .*'abc' must look like '1-20'"),
    _coil("objects-absent", *A, "--objects", "9", match=r"objects \[9\] are not in .* \(it holds \[1, 2\]\)"),
    _coil("alpha-0", "--alpha", "0", match=r"alpha=0\.0 must not be a multiple of 180"),
    _coil("alpha-180", "--alpha", "180", match=r"alpha=180\.0 must not be a multiple of 180"),
    _coil(
        "alpha-1e300", "--alpha", "1e300", match=r"--alpha must be degrees within \[-360, 360\], got '1e300'"
    ),
    _coil("threads-0", *A, "--threads", "0", match=threads_error("0")),
    _coil("threads-negative", *A, "--threads", "-2", match=threads_error("-2")),
    _coil(
        "workers-negative",
        *A,
        "--workers",
        "-1",
        match=r"--workers must be 'auto' or an integer >= 0, got '-1'",
    ),
    _coil(
        "workers-word",
        *A,
        "--workers",
        "many",
        match=r"--workers must be 'auto' or an integer >= 0, got 'many'",
    ),
]

# One bad entry in an otherwise good folder: (its name, how it is made, the error expected).
_ENTRIES = {
    "garbage-png": ("obj1__0.png", files.text, r"image .*obj1__0\.png.*" + NOT_AN_IMAGE),
    "empty-png": ("obj1__0.png", lambda p: p.write_bytes(b""), r"image .*obj1__0\.png.*" + EMPTY),
    "fifo-image": ("obj3__0.png", files.fifo, r"obj3__0\.png is a FIFO .*not a regular file"),
    "directory-image": ("obj3__0.png", os.mkdir, r"obj3__0\.png is a directory, not a regular file"),
}
#: The entries whose message does not say the cause yet (imageio's "could not find a backend").
COIL += [
    Case(
        id,
        command("coil", "--folder", "{tmp}", *A, setup=_coil_with(name, make)),
        match,
    )
    for id, (name, make, match) in _ENTRIES.items()
]
COIL.append(
    _coil(
        "sizes-differ",
        *A,
        match=r"obj2__0\.png must have shape .*\(1, 8, 8\) like the first image, got \(1, 16, 16\)",
        setup=_coil_sizes,
    )
)
OTHERS = [
    Case("demo-size-1", command("demo", "--size", "1", "--png", ""), r"--size=1 must be >= 2"),
    Case("demo-size-0", command("demo", "--size", "0", "--png", ""), r"--size=0 must be >= 2"),
    Case("demo-size-negative", command("demo", "--size", "-5", "--png", ""), r"--size=-5 must be >= 2"),
    Case(
        "demo-alpha-0",
        command("demo", "--alpha", "0", "--png", ""),
        r"--alpha=0(\.0)? must not be a multiple of 180",
    ),
    Case(
        "demo-alpha-inf",
        command("demo", "--alpha", "inf", "--png", ""),
        r"--alpha must be a finite number, got 'inf'",
    ),
    Case("demo-threads-0", command("demo", "--threads", "0", "--png", ""), threads_error("0")),
]

CASES = COIL + OTHERS


def _coil_record(out: Ran, tmp: Path) -> bool:
    """``coil --json {tmp}/r.json`` on :func:`files.coil` (noise, so any accuracy is sane):
    both objects, the test and gallery views that ``--alpha 10``'s default ranges give
    (38 and 82), an accuracy in [0, 100]."""
    record = json.loads((tmp / "r.json").read_text())
    assert record["n_test"] == 38 and record["n_train_views"] == 82, record
    assert 0 <= record["accuracy"] <= 100 and set(record["per_object"]) == {"1", "2"}, record
    return True


GOOD = [
    Good(
        "coil-threads-1",
        command(
            "coil", "--folder", "{tmp}", *A, "--threads", "1", "--json", "{tmp}/r.json", setup=files.coil
        ),
        _coil_record,
    ),
    Good(
        "coil-components-fraction",
        command(
            "coil",
            "--folder",
            "{tmp}",
            *A,
            "--components",
            "0.9",
            "--workers",
            "0",
            "--json",
            "{tmp}/r.json",
            setup=files.coil,
        ),
        _coil_record,
    ),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_command_line_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what


@pytest.mark.parametrize("case", params(GOOD))
def test_good_command_line_is_answered_right(case: Good, tmp_path: Path) -> None:
    kind, what = judge(case, tmp_path)
    assert kind == "right", what
