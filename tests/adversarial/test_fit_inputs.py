"""Bad input to ``eigview fit``: each must end in exit status 2 and a message that names
the flag, file or manifest line, the constraint and the value, with every input keeping
its bytes (the manifest's own format is attacked in test_manifest_inputs.py).

The manifest is :func:`tests.adversarial.views.manifest`: two rendered objects at 0, 10
and 20 degrees, 32 x 32; each case is judged by :func:`tests.adversarial.harness.outcome`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from tests.adversarial import files, views
from tests.adversarial.harness import Case, command, intact, outcome

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


SEEDS_AND_RANGES = [
    _fit("seeds-nan", "--seeds", "nan", *SYNTH, match=r"--seeds.*nan"),
    _fit("seeds-inf", "--seeds", "0", "inf", *SYNTH, match=r"--seeds.*inf"),
    _fit("seeds-text", "--seeds", "0", "ten", *SYNTH, match=r"--seeds.*ten"),
    _fit("seeds-M-2", "--seeds", "2", *SYNTH, match=r"--seeds 2: .*integer >= 3"),
    _fit("seeds-M-fraction", "--seeds", "3.5", *SYNTH, match=r"--seeds 3\.5: .*integer >= 3"),
    _fit("seeds-M-negative", "--seeds", "-4", *SYNTH, match=r"--seeds -4: .*integer >= 3"),
    _fit(
        "seeds-M-huge",
        "--seeds",
        "1e12",
        *SYNTH,
        match=r"--seeds asks for 1e\+12 seed views round the circle, more than the limit of 3600.*EIGVIEW_MAX_VIEWS",
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
    _fit("seeds-M-absent", "--seeds", "4", *SYNTH, match=r"'egg' has 3 view\(s\).*fewer than the 4 seeds"),
    _fit("center-nan", "--seeds", "4", "--center", "nan", *SYNTH, match=r"--center.*nan"),
    _fit("synth-step-0", *SEEDS, "--synth", "-10", "10", "0", match=r"synth step must be positive, got 0"),
    _fit("synth-nan", *SEEDS, "--synth", "nan", "10", "1", match=r"--synth.*nan"),
    _fit("synth-reversed", *SEEDS, "--synth", "10", "-10", "1", match=r"synth must have start <= stop"),
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
    _fit("reject-poses-step-0", *SEEDS, *SYNTH, "--reject-poses", "-5", "5", "0", match=r"reject-poses step"),
    _fit("reject-poses-nan", *SEEDS, *SYNTH, "--reject-poses", "nan", "5", "1", match=r"--reject-poses.*nan"),
    _fit(
        "reject-rate-0", *SEEDS, *SYNTH, "--reject-rate", "0", match=r"--reject-rate must be .*\(0, 1\).*'0'"
    ),
    _fit("reject-rate-1", *SEEDS, *SYNTH, "--reject-rate", "1", match=r"--reject-rate.*'1'"),
    _fit("reject-rate-nan", *SEEDS, *SYNTH, "--reject-rate", "nan", match=r"--reject-rate.*'nan'"),
    _fit("reject-rate-text", *SEEDS, *SYNTH, "--reject-rate", "most", match=r"--reject-rate.*'most'"),
]

OPTIONS = [
    _fit("size-0", *SEEDS, *SYNTH, "--size", "0", "32", match=r"--size.*0"),
    _fit("size-negative", *SEEDS, *SYNTH, "--size", "32", "-1", match=r"--size.*-1"),
    _fit(
        "size-huge",
        *SEEDS,
        *SYNTH,
        "--size",
        "100000",
        "100000",
        match=r"--size.*100000.*EIGVIEW_MAX_IMAGE_SIDE",
    ),
    _fit("size-1", *SEEDS, *SYNTH, "--size", "1", "1", match=r"--size=1 must be >= 2"),
    _fit("size-text", *SEEDS, *SYNTH, "--size", "big", "32", match=r"--size.*big"),
    _fit("channels-2", *SEEDS, *SYNTH, "--channels", "2", match=r"--channels.*2"),
    _fit(
        "background-300", *SEEDS, *SYNTH, "--background", "300,0,0", match=r"--background '300,0,0' must be"
    ),
    _fit("background-name", *SEEDS, *SYNTH, "--background", "red", match=r"--background 'red' must be"),
    _fit("background-two-values", *SEEDS, *SYNTH, "--background", "1,2", match=r"--background '1,2' must be"),
    _fit("background-nan", *SEEDS, *SYNTH, "--background", "nan", match=r"--background 'nan' must be"),
    _fit("tolerance-0", *SEEDS, *SYNTH, "--background", "auto", "--tolerance", "0", match=r"--tolerance '0'"),
    _fit(
        "tolerance-negative",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        "--tolerance",
        "-3",
        match=r"--tolerance.*-3",
    ),
    _fit(
        "tolerance-nan",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        "--tolerance",
        "nan",
        match=r"--tolerance.*nan",
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
        match=r"(--background|background).*(no object|all background|no foreground)",
    ),
    _fit("components-0", *SEEDS, *SYNTH, "-k", "0", match=r"--components.*0"),
    _fit(
        "components-above-views",
        *SEEDS,
        *SYNTH,
        "-k",
        "50",
        match=r"-k/--components 50 is more than the 10 gallery views allow",
    ),
    _fit("components-nan", *SEEDS, *SYNTH, "-k", "nan", match=r"--components.*nan"),
    _fit("extent-bogus", *SEEDS, *SYNTH, "--extent", "maybe", match=r"--extent.*maybe"),
    _fit("flow-bogus", *SEEDS, *SYNTH, "--flow", "magic", match=r"--flow.*magic"),
    _fit("elevation-95", *SEEDS, *SYNTH, "--elevation", "95", match=r"elevation=95\.0 must be an angle"),
    _fit("threads-0", *SEEDS, *SYNTH, "--threads", "0", match=r"--threads.*0"),
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
        r"--pattern.*not allowed with.*--manifest|--manifest.*--pattern",
    ),
    Case(
        "neither-manifest-nor-pattern",
        command("fit", *SEEDS, "--out", "{tmp}/m.pt"),
        r"--manifest.*--pattern",
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
        match=r"views\.csv.*(does not exist|cannot be read|No such)",
    ),
    _fit(
        "manifest-directory",
        *SEEDS,
        *SYNTH,
        setup=lambda t: os.mkdir(t / "views.csv"),
        match=r"views\.csv.*directory",
    ),
    _fit(
        "manifest-fifo",
        *SEEDS,
        *SYNTH,
        setup=lambda t: files.fifo(t / "views.csv"),
        match=r"views\.csv.*FIFO",
    ),
    _fit(
        "manifest-symlink-loop",
        *SEEDS,
        *SYNTH,
        setup=lambda t: os.symlink(t / "views.csv", t / "views.csv"),
        match=r"views\.csv.*(symbolic links|loop|cannot be read)",
    ),
    _fit(
        "manifest-header-only", *SEEDS, *SYNTH, setup=_only(""), match=r"views\.csv.*(no view|empty|holds no)"
    ),
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
        match=r"views\.csv line 2.*mask.*mask\.png.*\(16, 16\).*\(32, 32\)|mask\.png.*16.*32",
    ),
    _fit(
        "mask-all-false",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        setup=_masks(np.zeros((32, 32), np.uint8)),
        match=r"mask\.png.*(no object|all background|empty)|views\.csv line 2.*(no object|all background)",
    ),
    _fit(
        "rgba-empty-alpha",
        *SEEDS,
        *SYNTH,
        "--background",
        "auto",
        setup=_images(".png", np.zeros((32, 32, 4), np.uint8)),
        match=r"odd/0\.png.*(alpha|no object|all background)",
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
    _fit_over("out-is-the-manifest", "views.csv", r"--out.*views\.csv.*(input|--manifest)"),
    _fit_over("out-is-a-seed-image", "egg/0.png", r"--out.*egg/0\.png.*(input|manifest)"),
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
        r"--out.*(directory|--root)",
    ),
    _fit(
        "out-missing-folder",
        *SEEDS,
        *SYNTH,
        out="{tmp}/none/m.pt",
        match=r"--out.*none.*(folder|directory).*(not exist|missing)",
    ),
    _fit("out-directory", *SEEDS, *SYNTH, out="{tmp}/egg", match=r"--out.*egg.*directory"),
    _fit("out-dev-full", *SEEDS, *SYNTH, out="/dev/full", match=r"--out.*/dev/full"),
]

CASES = SEEDS_AND_RANGES + OPTIONS + MANIFEST_FILES + OUTPUTS


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_fit_input_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what
