"""Bad input to ``eigview fit``: each must end in exit status 2 and a message that names
the flag, file or manifest line, the constraint and the value, with every input keeping
its bytes (the manifest's own format is attacked in test_manifest_inputs.py).

The manifest is :func:`tests.adversarial.views.manifest`: two rendered objects at 0, 10
and 20 degrees, 32 x 32; each case is judged by :func:`tests.adversarial.harness.outcome`.
Good fits (``GOOD``: ``--threads 1``, a resize with the background estimated, a folder
pattern) must write a model of both objects with the components asked for.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from torch_eigview.io.checkpoint import load_recognizer

from tests.adversarial import files, views
from tests.adversarial.harness import (
    COMPONENTS,
    Case,
    Good,
    Ran,
    command,
    intact,
    judge,
    outcome,
    params,
    threads_error,
)

SEEDS = ("--seeds", "0", "10")
SYNTH = ("--synth", "-10", "10", "5", "-k", "4", "--quiet")


def _fit(id: str, *flags: str, match: str, setup: object = views.manifest, out: str = "{tmp}/m.pt") -> Case:
    """``eigview fit --manifest {tmp}/views.csv FLAGS --out OUT`` on a manifest made by ``setup``."""
    argv = ("fit", "--manifest", "{tmp}/views.csv", *flags, "--out", out)
    return Case(id, command(*argv, setup=setup), match)  # type: ignore[arg-type]


def _with_rows(*rows: str, header: str = "path,object,azimuth") -> object:
    def setup(tmp: Path) -> None:
        views.manifest(tmp, "".join(r + "\n" for r in rows), header=header)

    return setup


def _only(rows: str, header: str = "path,object,azimuth") -> object:
    """views.csv with the header and ``rows`` only (the rendered images beside it)."""

    def setup(tmp: Path) -> None:
        views.manifest(tmp)
        (tmp / "views.csv").write_text(f"{header}\n{rows}", encoding="utf-8")

    return setup


def _images(name: str, array: np.ndarray) -> object:
    """A third object ``odd`` whose views at 0 and 10 are ``array``, written as ``name``."""

    def setup(tmp: Path) -> None:
        extra = ""
        for az in (0, 10):
            views.png(tmp / "odd" / f"{az}{name}", array)
            extra += f"odd/{az}{name},odd,{az}\n"
        views.manifest(tmp, extra)

    return setup


def _masks(mask: np.ndarray) -> object:
    """Every view with a mask column naming ``mask`` (written once as mask.png)."""

    def setup(tmp: Path) -> None:
        views.manifest(tmp)
        views.png(tmp / "mask.png", mask)
        lines = (tmp / "views.csv").read_text().splitlines()
        rows = [lines[0] + ",mask"] + [line + ",mask.png" for line in lines[1:]]
        (tmp / "views.csv").write_text("\n".join(rows) + "\n")

    return setup


#: ``--reject-rate VALUE`` and ``--background VALUE`` refused by argparse (``.format(value)``).
REJECT_RATE = r"--reject-rate must be a number in \(0, 1\), got '{}'"
BACKGROUND = r"--background '{}' must be keep, auto, or a colour"

SEEDS_AND_RANGES = [
    _fit("seeds-nan", "--seeds", "nan", *SYNTH, match=r"--seeds must be a finite number, got 'nan'"),
    _fit("seeds-inf", "--seeds", "0", "inf", *SYNTH, match=r"--seeds must be a finite number, got 'inf'"),
    _fit("seeds-text", "--seeds", "0", "ten", *SYNTH, match=r"--seeds must be a finite number, got 'ten'"),
    _fit("seeds-one", "--seeds", "10", *SYNTH, match=r"--seeds 10 needs two or more azimuths.*--circle M"),
    _fit(
        "synth-past-a-quarter-turn",
        "--seeds",
        "0",
        "20",
        "--synth",
        "-20",
        "100",
        "5",
        match=r"--synth asks for views 100 degrees from the seed .* --seeds at 0, 20 degrees; .*less than 90 degrees",
    ),
    _fit("circle-2", "--circle", "2", *SYNTH, match=r"--circle=2 must be >= 3"),
    _fit("circle-fraction", "--circle", "3.5", *SYNTH, match=r"--circle must be an integer, got '3\.5'"),
    _fit("circle-negative", "--circle", "-4", *SYNTH, match=r"--circle=-4 must be >= 3"),
    _fit(
        "circle-and-seeds",
        "--circle",
        "4",
        "--seeds",
        "0",
        "10",
        match=r"--seeds: not allowed with argument --circle",
    ),
    _fit(
        "circle-huge",
        "--circle",
        "1000000000000",
        *SYNTH,
        match=r"--circle asks for 1e\+12 seed views round the circle, more than the limit of 3600.*EIGVIEW_MAX_VIEWS",
    ),
    _fit("seeds-repeat", "--seeds", "0", "0", *SYNTH, match=r"--seeds 0 0 repeats an azimuth"),
    _fit("seeds-repeat-wrapped", "--seeds", "0", "360", *SYNTH, match=r"--seeds 0 360 repeats an azimuth"),
    _fit(
        "seeds-half-turn",
        "--seeds",
        "0",
        "180",
        *SYNTH,
        setup=_with_rows("egg/0.png,egg,180", "head/0.png,head,180"),
        match=r"--seeds 0 180 puts consecutive seeds 180 degrees apart",
    ),
    _fit("seeds-absent", "--seeds", "0", "15", *SYNTH, match=r"'egg' has no view at the seed azimuth 15"),
    _fit("circle-absent", "--circle", "4", *SYNTH, match=r"'egg' has 3 view\(s\).*fewer than the 4 seeds"),
    _fit(
        "center-nan",
        "--seeds",
        "4",
        "--center",
        "nan",
        *SYNTH,
        match=r"--center must be a finite number, got 'nan'",
    ),
    _fit("synth-step-0", *SEEDS, "--synth", "-10", "10", "0", match=r"--synth step must be positive, got 0"),
    _fit(
        "synth-nan", *SEEDS, "--synth", "nan", "10", "1", match=r"--synth must be a finite number, got 'nan'"
    ),
    _fit(
        "synth-reversed",
        *SEEDS,
        "--synth",
        "10",
        "-10",
        "1",
        match=r"--synth must have start <= stop, got start=10",
    ),
    _fit(
        "synth-tiny-step",
        *SEEDS,
        "--synth",
        "-20",
        "20",
        "1e-9",
        match=r"--synth asks for 4e\+10 views per object, more than the limit.*EIGVIEW_MAX_VIEWS",
    ),
    _fit(
        "synth-tiny-step-circle",
        "--seeds",
        "3",
        "--synth",
        "0",
        "1",
        "1e-9",
        match=r"--synth asks for 1e\+09 views per object, more than the limit.*EIGVIEW_MAX_VIEWS",
    ),
    _fit(
        "reject-poses-tiny-step",
        *SEEDS,
        *SYNTH,
        "--reject-poses",
        "-20",
        "20",
        "1e-9",
        match=r"--reject-poses asks for 4e\+10 views per object, more than the limit.*EIGVIEW_MAX_VIEWS",
    ),
    _fit(
        "reject-poses-gallery-only",
        *SEEDS,
        *SYNTH,
        "--reject-poses",
        "0",
        "0",
        "1",
        match=r"--reject-poses .* holds gallery angles only",
    ),
    _fit(
        "reject-poses-step-0",
        *SEEDS,
        *SYNTH,
        "--reject-poses",
        "-5",
        "5",
        "0",
        match=r"--reject-poses step must be positive, got 0",
    ),
    _fit(
        "reject-poses-nan",
        *SEEDS,
        *SYNTH,
        "--reject-poses",
        "nan",
        "5",
        "1",
        match=r"--reject-poses must be a finite number, got 'nan'",
    ),
    _fit("reject-rate-0", *SEEDS, *SYNTH, "--reject-rate", "0", match=REJECT_RATE.format("0")),
    *(
        _fit(f"reject-rate-{v}", *SEEDS, *SYNTH, "--reject-rate", v, match=REJECT_RATE.format(v))
        for v in ("1", "nan", "most")
    ),
]

OPTIONS = [
    _fit("size-0", *SEEDS, *SYNTH, "--size", "0", "32", match=r"--size=0 must be >= 2"),
    _fit("size-negative", *SEEDS, *SYNTH, "--size", "32", "-1", match=r"--size=-1 must be >= 2"),
    _fit(
        "size-huge",
        *SEEDS,
        *SYNTH,
        "--size",
        "100000",
        "100000",
        match=r"--size asks for 100000 pixels per image side, more than the limit.*EIGVIEW_MAX_IMAGE_SIDE",
    ),
    _fit("size-1", *SEEDS, *SYNTH, "--size", "1", "1", match=r"--size=1 must be >= 2"),
    _fit("size-text", *SEEDS, *SYNTH, "--size", "big", "32", match=r"--size must be an integer, got 'big'"),
    _fit("channels-2", *SEEDS, *SYNTH, "--channels", "2", match=r"--channels: invalid choice: 2"),
    _fit("background-300", *SEEDS, *SYNTH, "--background", "300,0,0", match=BACKGROUND.format("300,0,0")),
    _fit("background-name", *SEEDS, *SYNTH, "--background", "red", match=BACKGROUND.format("red")),
    _fit("background-two-values", *SEEDS, *SYNTH, "--background", "1,2", match=BACKGROUND.format("1,2")),
    _fit("background-nan", *SEEDS, *SYNTH, "--background", "nan", match=BACKGROUND.format("nan")),
    _fit(
        "tolerance-0",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        "--tolerance",
        "0",
        match=r"--tolerance '0' must be a number in \(0, ",
    ),
    _fit(
        "tolerance-negative",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        "--tolerance",
        "-3",
        match=r"--tolerance '-3' must be a number in \(0, ",
    ),
    _fit(
        "tolerance-nan",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        "--tolerance",
        "nan",
        match=r"--tolerance must be a finite number, got 'nan'",
    ),
    _fit(
        "tolerance-with-keep",
        *SEEDS,
        *SYNTH,
        "--tolerance",
        "10",
        match=r"--tolerance goes with --background",
    ),
    _fit(
        "background-leaves-no-object",
        *SEEDS,
        *SYNTH,
        "--background",
        "0,0,0",
        "--tolerance",
        "441",
        match=r"views\.csv line 2: .*egg/0\.png: background=\(0\).*leaves no object",
    ),
    _fit("components-0", *SEEDS, *SYNTH, "-k", "0", match=COMPONENTS.format("0")),
    _fit(
        "components-above-views",
        *SEEDS,
        *SYNTH,
        "-k",
        "50",
        match=r"-k/--components 50 is more than the 10 gallery views allow",
    ),
    _fit("components-nan", *SEEDS, *SYNTH, "-k", "nan", match=COMPONENTS.format("nan")),
    _fit("extent-bogus", *SEEDS, *SYNTH, "--extent", "maybe", match=r"--extent: invalid choice: 'maybe'"),
    _fit("flow-bogus", *SEEDS, *SYNTH, "--flow", "magic", match=r"--flow: invalid choice: 'magic'"),
    _fit(
        "elevation-95",
        *SEEDS,
        *SYNTH,
        "--elevation",
        "95",
        match=r"elevation=95(\.0)? must be an angle in degrees in \(-90, 90\)",
    ),
    _fit("threads-0", *SEEDS, *SYNTH, "--threads", "0", match=threads_error("0")),
    Case(
        "manifest-and-pattern",
        command(
            "fit",
            "--manifest",
            "a.csv",
            "--pattern",
            "{{object}}/{{azimuth}}.png",
            *SEEDS,
            "--out",
            "{tmp}/m",
        ),
        r"--pattern: not allowed with argument --manifest",
    ),
    Case(
        "neither-manifest-nor-pattern",
        command("fit", *SEEDS, "--out", "{tmp}/m.pt"),
        r"one of the arguments --manifest --pattern is required",
    ),
    Case(
        "pattern-without-root",
        command("fit", "--pattern", "{{object}}/{{azimuth}}.png", *SEEDS, *SYNTH, "--out", "{tmp}/m.pt"),
        r"--pattern '\{object\}/\{azimuth\}\.png' needs --root",
    ),
    _fit("root-with-manifest", *SEEDS, *SYNTH, "--root", "{tmp}", match=r"--root .* goes with --pattern"),
]

MANIFEST_FILES = [
    _fit(
        "manifest-missing",
        *SEEDS,
        *SYNTH,
        setup=lambda t: None,
        match=r"views\.csv does not exist",
    ),
    _fit(
        "manifest-directory",
        *SEEDS,
        *SYNTH,
        setup=lambda t: os.mkdir(t / "views.csv"),
        match=r"views\.csv is a directory, not a regular file",
    ),
    _fit(
        "manifest-fifo",
        *SEEDS,
        *SYNTH,
        setup=lambda t: files.fifo(t / "views.csv"),
        match=r"views\.csv is a FIFO .*not a regular file",
    ),
    _fit(
        "manifest-symlink-loop",
        *SEEDS,
        *SYNTH,
        setup=lambda t: os.symlink(t / "views.csv", t / "views.csv"),
        match=r"views\.csv cannot be used: Too many levels of symbolic links",
    ),
    _fit("manifest-header-only", *SEEDS, *SYNTH, setup=_only(""), match=r"views\.csv lists no view"),
    _fit(
        "object-one-view",
        *SEEDS,
        *SYNTH,
        setup=_with_rows("egg/0.png,lone,0"),
        match=r"object 'lone' has 1 view\(s\) in .*views\.csv, fewer than the 2 seeds",
    ),
    _fit(
        "images-1x1",
        *SEEDS,
        *SYNTH,
        setup=lambda t: _tiny(t, 1),
        match=r"views\.csv line 2: image .*0\.png is \(H, W\)=\(1, 1\), smaller than 2 x 2: give --size",
    ),
    _fit(
        "mask-other-size",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        setup=_masks(np.full((16, 16), 255, np.uint8)),
        match=r"views\.csv line 2: mask .*mask\.png has size \(H, W\)=\(16, 16\), its image .*\(32, 32\): they must match",
    ),
    _fit(
        "mask-all-false",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        setup=_masks(np.zeros((32, 32), np.uint8)),
        match=r"views\.csv line 2: .*egg/0\.png: masks\[0\] is all background",
    ),
    _fit(
        "rgba-empty-alpha",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        setup=_images(".png", np.zeros((32, 32, 4), np.uint8)),
        match=r"views\.csv line 8: .*odd/0\.png: masks\[0\] is all background",
    ),
]


def _tiny(tmp: Path, side: int) -> None:
    """A manifest of one object seen at 0 and 10 degrees in side x side images."""
    rng = np.random.default_rng(0)
    for az in (0, 10):
        views.png(tmp / f"{az}.png", (rng.random((side, side)) * 255).astype(np.uint8))
    (tmp / "views.csv").write_text("path,object,azimuth\n0.png,a,0\n10.png,a,10\n")


def _fit_over(id: str, name: str, match: str) -> Case:
    """``eigview fit --out {tmp}/NAME`` where NAME is one of its inputs, which must keep its bytes."""
    argv = ("fit", "--manifest", "{tmp}/views.csv", *SEEDS, *SYNTH, "--out", "{tmp}/" + name)
    return Case(id, intact(command(*argv, setup=views.manifest), name), match)


OUTPUTS = [
    _fit_over("out-is-the-manifest", "views.csv", r"--out=.*views\.csv'? is the same file as --manifest"),
    _fit_over(
        "out-is-a-seed-image", "egg/0.png", r"--out=.*egg/0\.png'? is the image of .*views\.csv line 2"
    ),
    Case(
        "out-is-the-pattern-root",
        command(
            "fit",
            "--pattern",
            "{{object}}/{{azimuth}}.png",
            "--root",
            "{tmp}",
            *SEEDS,
            *SYNTH,
            "--out",
            "{tmp}",
            setup=views.manifest,
        ),
        r"--out=.*'? is a directory",
    ),
    _fit(
        "out-missing-folder",
        *SEEDS,
        *SYNTH,
        out="{tmp}/none/m.pt",
        match=r"--out=.*none/m\.pt'?: the folder .*none'? does not exist",
    ),
    _fit("out-directory", *SEEDS, *SYNTH, out="{tmp}/egg", match=r"--out=.*egg'? is a directory"),
    _fit(
        "out-dev-full",
        *SEEDS,
        *SYNTH,
        out="/dev/full",
        match=r"--out='/dev/full' is a character device, not a regular file",
    ),
]

CASES = SEEDS_AND_RANGES + OPTIONS + MANIFEST_FILES + OUTPUTS


def _model_of(shape: tuple[int, int, int]) -> object:
    """The check of a fit: m.pt holds a recognizer of both objects, k=4, of ``shape`` views
    (5 synthesized poses each, from -10 to 10 degrees), as the command says it wrote."""

    def check(out: Ran, tmp: Path) -> bool:
        recognizer, _ = load_recognizer(tmp / "m.pt")
        assert recognizer.codes.shape == (10, 4), recognizer.codes.shape
        assert recognizer.labels.unique().numel() == 2, recognizer.labels
        assert recognizer.projection.image_shape == shape, recognizer.projection.image_shape
        assert f"2 objects, 10 gallery views of (C, H, W)={shape}, k=4" in out.stdout, out.stdout
        return True

    return check


GOOD = [
    Good(
        "threads-1",
        command(
            "fit",
            "--manifest",
            "{tmp}/views.csv",
            *SEEDS,
            *SYNTH,
            "--threads",
            "1",
            "--out",
            "{tmp}/m.pt",
            setup=views.manifest,
        ),
        _model_of((1, 32, 32)),
    ),
    Good(
        "size-and-background-auto",
        command(
            "fit",
            "--manifest",
            "{tmp}/views.csv",
            *SEEDS,
            *SYNTH,
            "--size",
            "16",
            "16",
            "--background",
            "auto",
            "--out",
            "{tmp}/m.pt",
            setup=views.manifest,
        ),
        _model_of((1, 16, 16)),
    ),
    Good(
        "pattern",
        command(
            "fit",
            "--pattern",
            "{{object}}/{{azimuth}}.png",
            "--root",
            "{tmp}",
            *SEEDS,
            *SYNTH,
            "--out",
            "{tmp}/m.pt",
            setup=views.manifest,
        ),
        _model_of((1, 32, 32)),
    ),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_fit_input_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what


@pytest.mark.parametrize("case", params(GOOD))
def test_good_fit_is_answered_right(case: Good, tmp_path: Path) -> None:
    kind, what = judge(case, tmp_path)
    assert kind == "right", what
