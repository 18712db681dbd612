"""Bad input to ``eigview coil``, ``demo``, ``synth`` and ``bench``: each must end in exit
status 2 and a message that names the flag or file, the constraint and the value (the
commands' files, models, images and outputs, are in test_cli_files.py).

The cases are the ones found missing from ``tests/apps`` and ``tests/test_faults.py``; each
is judged by :func:`tests.adversarial.harness.outcome`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import skimage.io

from tests.adversarial import files
from tests.adversarial.harness import Case, command, outcome

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
    """``eigview coil --root {tmp} FLAGS`` on a COIL folder made by ``setup``."""
    return Case(id, command("coil", "--root", "{tmp}", *flags, setup=setup), match)  # type: ignore[arg-type]


COIL = [
    Case(
        "root-missing",
        command("coil", "--root", "{tmp}/nope", *A),
        r"nope'? \(given with --root\) must be an existing directory",
    ),
    Case(
        "root-is-a-file",
        command("coil", "--root", "{tmp}/f.txt", *A, setup=lambda t: files.text(t / "f.txt")),
        r"f\.txt'? \(given with --root\) must be an existing directory",
    ),
    Case(
        "root-empty",
        command("coil", "--root", "{tmp}/empty", *A, setup=_empty_dir),
        r"empty'? holds no COIL files",
    ),
    _coil("components-0", *A, "--components", "0", match=r"--components.*0"),
    _coil("components-negative", *A, "--components", "-3", match=r"--components.*-3"),
    _coil("components-1.5", *A, "--components", "1.5", match=r"--components.*1\.5"),
    _coil("components-nan", *A, "--components", "nan", match=r"--components.*nan"),
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
    _coil("seeds-0", "--seeds", "0", match=r"--seeds=0 must be >= 2"),
    _coil("seeds-1", "--seeds", "1", match=r"--seeds=1 must be >= 2"),
    _coil(
        "dense-step-0",
        "--seeds",
        "4",
        "--method",
        "dense",
        "--dense-step",
        "0",
        match=r"--dense-step=0 must be a positive multiple",
    ),
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
    _coil("elevation-nan", *A, "--elevation", "nan", match=r"elevation=nan must be an angle"),
    _coil("objects-0", *A, "--objects", "0", match=r"--objects.*0"),
    _coil("objects-reversed", *A, "--objects", "5-3", match=r"--objects.*5-3"),
    _coil("objects-text", *A, "--objects", "abc", match=r"--objects.*abc"),
    _coil("objects-absent", *A, "--objects", "9", match=r"objects \[9\] are not in .* \(it holds \[1, 2\]\)"),
    _coil("alpha-0", "--alpha", "0", match=r"alpha=0\.0 must not be a multiple of 180"),
    _coil("alpha-180", "--alpha", "180", match=r"alpha=180\.0 must not be a multiple of 180"),
    _coil("alpha-1e300", "--alpha", "1e300", match=r"alpha=1e\+300 must be an angle .* \[-360, 360\]"),
    _coil("threads-0", *A, "--threads", "0", match=r"--threads.*0"),
    _coil("threads-negative", *A, "--threads", "-2", match=r"--threads.*-2"),
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
    "garbage-png": ("obj1__0.png", files.text, r"cannot read image .*obj1__0\.png"),
    "empty-png": ("obj1__0.png", lambda p: p.write_bytes(b""), r"cannot read image .*obj1__0\.png"),
    "fifo-image": ("obj3__0.png", files.fifo, r"obj3__0\.png is a FIFO .*not a regular file"),
    "directory-image": ("obj3__0.png", os.mkdir, r"obj3__0\.png is a directory, not a regular file"),
}
COIL += [
    _coil(id, *A, match=match, setup=_coil_with(name, make)) for id, (name, make, match) in _ENTRIES.items()
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
    Case("demo-size-0", command("demo", "--size", "0", "--png", ""), r"--size.*0"),
    Case("demo-size-negative", command("demo", "--size", "-5", "--png", ""), r"--size.*-5"),
    Case("demo-alpha-0", command("demo", "--alpha", "0", "--png", ""), r"alpha.*0"),
    Case("demo-alpha-inf", command("demo", "--alpha", "inf", "--png", ""), r"--alpha.*inf"),
    Case("demo-threads-0", command("demo", "--threads", "0", "--png", ""), r"--threads.*0"),
    Case(
        "demo-correspondences",
        command("demo", "--correspondences", "magic", "--png", ""),
        r"--correspondences.*magic",
    ),
    Case("synth-shape-unknown", command("synth", "--shapes", "cube"), r"--shapes.*cube"),
    Case("synth-shapes-empty", command("synth", "--shapes", ""), r"--shapes.*''"),
    Case("synth-alpha-0", command("synth", "--alpha", "0"), r"alpha.*0"),
    Case("synth-alpha-nan", command("synth", "--alpha", "nan"), r"--alpha.*nan"),
    Case(
        "synth-size-3",
        command("synth", "--size", "3"),
        r"rendered at \(3, 3\) pixels give too few distinct views for 15.*--size.*--shapes",
    ),
    Case("synth-views-4", command("synth", "--views", "4"), r"--views.*4"),
    Case("bench-section-unknown", command("bench", "--sections", "nope"), r"--sections.*nope"),
    Case(
        "bench-root-missing",
        command("bench", "--sections", "eigen", "--root", "{tmp}/none"),
        r"--root='.*none' is not an existing folder",
    ),
    Case("bench-threads-0", command("bench", "--quick", "--threads", "0"), r"--threads.*0"),
]

CASES = COIL + OTHERS


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_command_line_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what
