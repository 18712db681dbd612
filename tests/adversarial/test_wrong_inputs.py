"""Inputs that are well-formed but wrong (issue 41, classes 1 and 5): each must end in a
clear error, or where the input may be meant, a warning, that names the file, flag or line
and the number; never a silent answer, and never an error that blames something else.

- numbers that Python's ``float`` reads but a person did not mean (``1_0``, ``١٠``);
- masks that mark the backdrop as the object (inverted masks and alpha channels);
- a background colour found nowhere on an image's border (it would remove nothing);
- ``--center`` beside listed seeds (it would be ignored), angles past a full turn;
- seed views of another aspect ratio (squeezed by the resize);
- two views at one azimuth that are not other elevations;
- a first image past the side limit (blamed on the file, with ``--size``), ``demo --size 2``,
  numbers in exponent notation after a flag (``--test -1e300 1e300``), maps of another size.

Good inputs beside them must still be answered right: correct masks, opaque alpha
channels, the same aspect at another size, ``--center`` with ``--circle``, exponents.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import skimage.io
import torch

from torch_eigview.io.checkpoint import load_recognizer
from torch_eigview.warp import NovelViewWarp, SparseViewOperator

from tests.adversarial import files, views
from tests.adversarial.harness import Case, Good, Ran, command, judge, outcome, params

SEEDS = ("--seeds", "0", "10")
SYNTH = ("--synth", "-10", "10", "5", "-k", "4", "--quiet")


def _fit(
    id: str, *flags: str, match: str, setup: object = views.manifest, warns: bool = False, seeds: bool = True
) -> Case:
    argv = (
        "fit",
        "--manifest",
        "{tmp}/views.csv",
        *(SEEDS if seeds else ()),
        *SYNTH,
        *flags,
        "--out",
        "{tmp}/m.pt",
    )
    return Case(id, command(*argv, setup=setup), match, warns=warns)  # type: ignore[arg-type]


def _rows(rows: str) -> object:
    """views.csv with the rendered images and exactly ``rows`` after the header."""

    def setup(tmp: Path) -> None:
        views.manifest(tmp)
        (tmp / "views.csv").write_text("path,object,azimuth\n" + rows, encoding="utf-8")

    return setup


def _object_masks(transform: object) -> object:
    """Every view with a mask file: its object (pixels > 0), passed through ``transform``."""

    def setup(tmp: Path) -> None:
        path = views.manifest(tmp)
        lines = path.read_text().splitlines()
        rows = [lines[0] + ",mask"]
        for line in lines[1:]:
            image = np.asarray(skimage.io.imread(tmp / line.split(",")[0]))
            mask = transform(image > 0)  # type: ignore[operator]
            name = line.split(",")[0].replace(".png", "_mask.png")
            views.png(tmp / name, mask.astype(np.uint8) * 255)
            rows.append(f"{line},{name}")
        path.write_text("\n".join(rows) + "\n")

    return setup


def _half_border(mask: np.ndarray) -> np.ndarray:
    """The object's mask with the left and right image columns marked too (about half the border)."""
    out = mask.copy()
    out[:, :1] = True
    out[:, -1:] = True
    return out


def _rgba(alpha_of: object) -> object:
    """Every view as RGBA with the alpha channel ``alpha_of(object mask)``."""

    def setup(tmp: Path) -> None:
        path = views.manifest(tmp)
        for line in path.read_text().splitlines()[1:]:
            name = line.split(",")[0]
            gray = np.asarray(skimage.io.imread(tmp / name))
            alpha = alpha_of(gray > 0)  # type: ignore[operator]
            rgba = np.stack([gray, gray, gray, alpha.astype(np.uint8) * 255], axis=-1)
            views.png(tmp / name, rgba)

    return setup


def _wide_seed(tmp: Path) -> None:
    """egg's view at 10 degrees written 32 x 64 (another aspect ratio) among 32 x 32 views."""
    views.manifest(tmp)
    image = np.asarray(skimage.io.imread(tmp / "egg" / "10.png"))
    views.png(tmp / "egg" / "10.png", np.repeat(image, 2, axis=1))


def _big_first(tmp: Path) -> None:
    """egg's view at 0 degrees written 600 x 600, past the default side limit of 512."""
    views.manifest(tmp)
    views.png(tmp / "egg" / "0.png", np.zeros((600, 600), np.uint8))


def _maps_for_other_images(tmp: Path) -> object:
    """SparseViewOperator.from_maps with 8 x 8 images and maps built for 16 x 16 views."""
    from torch_eigview.geometry.correspondence import Correspondence

    zero, valid = torch.zeros(1, 16, 16), torch.ones(1, 16, 16, dtype=torch.bool)
    corr = Correspondence(zero, zero, valid, valid)
    maps = NovelViewWarp(10.0).maps(corr, torch.tensor([5.0]))
    return SparseViewOperator.from_maps(torch.rand(2, 1, 8, 8), maps)


NUMBERS = [
    _fit(
        "azimuth-underscore",
        setup=_rows("egg/0.png,egg,0\negg/10.png,egg,1_0\n"),
        match=r"views\.csv line 3: azimuth='1_0' must be a number of degrees in decimal digits",
    ),
    _fit(
        "azimuth-arabic-digits",
        setup=_rows("egg/0.png,egg,0\negg/10.png,egg,١٠\n"),
        match=r"views\.csv line 3: azimuth='١٠' must be a number of degrees in decimal digits",
    ),
    Case(
        "seeds-underscore",
        command("fit", "--manifest", "{tmp}/views.csv", "--seeds", "0", "1_0", "--out", "{tmp}/m.pt"),
        r"--seeds must be a finite number, got '1_0'",
    ),
    _fit("components-underscore", "-k", "1_0", match=r"--components must be an int.*got '1_0'"),
    _fit(
        "threads-fullwidth-digit",
        "--threads",
        "２",
        match=r"--threads must be an integer >= 1, got '２'",
    ),
    _fit(
        "background-underscore",
        "--background",
        "2_55,0,0",
        match=r"--background .*'2_55,0,0'",
    ),
    _fit(
        "center-1e300-fit",
        "--center",
        "1e300",
        match=r"--center must be degrees within \[-360, 360\], got '1e300'",
    ),
    Case(
        "coil-center-1e300",
        command("coil", "--folder", "{tmp}", "--alpha", "10", "--center", "1e300", setup=files.coil),
        r"--center must be degrees within \[-360, 360\], got '1e300'",
    ),
    Case(
        "coil-test-exponents",
        command("coil", "--folder", "{tmp}", "--alpha", "10", "--test", "-1e300", "1e300", setup=files.coil),
        r"--test must be degrees within \[-360, 360\], got '-1e300'",
    ),
    Case(
        "coil-alpha-negative-exponent",
        command("coil", "--folder", "{tmp}", "--alpha", "-1e3", setup=files.coil),
        r"--alpha must be degrees within \[-360, 360\], got '-1e3'",
    ),
]

MASKS = [
    _fit(
        "masks-inverted",
        "--background",
        "auto",
        setup=_object_masks(np.logical_not),
        match=r"views\.csv line 2: mask .*egg/0_mask\.png marks 100% of the image border as object: is it inverted",
    ),
    _fit(
        "masks-inverted-default-background",
        setup=_object_masks(np.logical_not),
        match=r"mask .*_mask\.png marks 100% of the image border as object: is it inverted",
    ),
    _fit(
        "alpha-inverted",
        "--background",
        "auto",
        setup=_rgba(np.logical_not),
        match=r"the alpha channel of .*egg/0\.png marks 100% of the image border as object: is it inverted",
    ),
    _fit(
        "masks-half-the-border",
        "--background",
        "auto",
        setup=_object_masks(_half_border),
        match=r"mask .*_mask\.png marks 5\d% of the image border as object: is it inverted",
        warns=True,
    ),
    _fit(
        "colour-found-nowhere",
        "--background",
        "255,0,0",
        "--tolerance",
        "10",
        match=r"views\.csv line 2: .*egg/0\.png: background=\(0\.213\) ± 0\.0392 \(given.*matches no pixel of the "
        r"border .*median colour is \(0\): nothing would be removed",
    ),
    _fit(
        "colour-white-on-black",
        "--background",
        "255,255,255",
        "--tolerance",
        "30",
        match=r"background=\(1\) ± 0\.118 .*matches no pixel of the border",
    ),
    _fit(
        "colour-removes-everything",
        "--background",
        "0,0,0",
        "--tolerance",
        "441",
        match=r"background=\(0\) ± 1\.73 .*leaves no object",
    ),
]

SEEDS_AND_SIZES = [
    _fit(
        "center-with-listed-seeds",
        "--center",
        "50",
        match=r"--center 50 goes with --circle .*with --seeds the first listed azimuth \(0 10\) is the centre",
    ),
    _fit(
        "circle-of-3",
        "--circle",
        "3",
        seeds=False,
        match=r"--circle 3 puts the seeds 120 degrees apart, but a view is synthesized less than 90 degrees .*"
        r"give --circle 4 or more",
    ),
    _fit(
        "azimuths-within-tolerance",
        setup=_rows(
            "egg/0.png,egg,0\negg/10.png,egg,10\negg/20.png,egg,10.0000001\nhead/0.png,head,0\nhead/10.png,head,10\n"
        ),
        match=r"object 'egg' has 2 views at the seed azimuth 10 degrees \(azimuths 10, 10\.0000001, within 1e-06 "
        r"degrees of each other\)",
    ),
    _fit(
        "seed-of-another-aspect",
        "--size",
        "32",
        "32",
        setup=_wide_seed,
        match=r"views\.csv line 3: image .*egg/10\.png is 32 x 64 \(H x W\), another aspect ratio than the first "
        r"image .*egg/0\.png \(32 x 32\)",
        warns=True,
    ),
    _fit(
        "seed-of-another-aspect-without-size",
        setup=_wide_seed,
        match=r"image .*egg/10\.png is 32 x 64 \(H x W\), another aspect ratio",
        warns=True,
    ),
    _fit(
        "first-image-past-the-side-limit",
        setup=_big_first,
        match=r"views\.csv line 2: the first seed view .*egg/0\.png asks for 600 pixels per side, more than the "
        r"limit of 512.*give --size H W",
    ),
    Case(
        "demo-size-2",
        command("demo", "--size", "2", "--png", ""),
        r"rendered at \(2, 2\) pixels give too few distinct views .*render larger views \(--size\)",
    ),
    Case(
        "maps-for-other-images",
        _maps_for_other_images,
        r"images are \(H, W\)=\(8, 8\), the maps were built for \(H, W\)=\(16, 16\)",
    ),
]

CASES = NUMBERS + MASKS + SEEDS_AND_SIZES


def _fitted(extra: str = "") -> object:
    """The check of a good fit: m.pt of both objects, k=4, and no warning unless ``extra`` matches one."""

    def check(out: Ran, tmp: Path) -> bool:
        recognizer, _ = load_recognizer(tmp / "m.pt")
        assert recognizer.labels.unique().numel() == 2, recognizer.labels
        assert recognizer.codes.shape[1] == 4, recognizer.codes.shape
        said = [line for line in out.stderr.splitlines() if "warning:" in line]
        assert all(extra and extra in line for line in said), f"unexpected warnings: {said}"
        return True

    return check


def _good_fit(id: str, *flags: str, setup: object = views.manifest, seeds: bool = True) -> Good:
    argv = (
        "fit",
        "--manifest",
        "{tmp}/views.csv",
        *(SEEDS if seeds else ()),
        *SYNTH,
        *flags,
        "--out",
        "{tmp}/m.pt",
    )
    return Good(id, command(*argv, setup=setup), _fitted())  # type: ignore[arg-type]


def _coil_ran(out: Ran, tmp: Path) -> bool:
    record = json.loads((tmp / "r.json").read_text())
    assert 0 <= record["accuracy"] <= 100, record
    return True


GOOD = [
    _good_fit("masks-of-the-object", "--background", "auto", setup=_object_masks(lambda m: m)),
    _good_fit("alpha-of-the-object", "--background", "auto", setup=_rgba(lambda m: m)),
    _good_fit("alpha-opaque", "--background", "auto", setup=_rgba(lambda m: np.ones_like(m))),
    _good_fit("colour-of-the-backdrop", "--background", "0,0,0", "--tolerance", "10"),
    _good_fit("same-aspect-other-size", "--size", "16", "16"),
    _good_fit(
        "center-with-circle",
        "--circle",
        "4",
        "--center",
        "-360",
        setup=_rows(
            "".join(f"{o}/{a % 30}.png,{o},{a * 9}\n" for o in ("egg", "head") for a in (0, 10, 20, 30))
        ),
        seeds=False,
    ),
    _good_fit(
        "azimuths-in-exponent-notation",
        setup=_rows(
            "egg/0.png,egg,0e0\negg/10.png,egg,1e1\negg/20.png,egg,+20.0\nhead/0.png,head,-0\nhead/10.png,head,10.\n"
        ),
    ),
    Good(
        "coil-negative-exponents",
        command(
            "coil",
            "--folder",
            "{tmp}",
            "--alpha",
            "1e1",
            "--test",
            "-4.5e1",
            "4.5e1",
            "--json",
            "{tmp}/r.json",
            setup=files.coil,
        ),
        _coil_ran,
    ),
]


@pytest.mark.parametrize("case", params(CASES))
def test_wrong_input_gets_a_clear_answer(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what


@pytest.mark.parametrize("case", params(GOOD))
def test_good_input_is_answered_right(case: Good, tmp_path: Path) -> None:
    kind, what = judge(case, tmp_path)
    assert kind == "right", what
