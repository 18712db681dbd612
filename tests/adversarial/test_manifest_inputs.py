"""Bad manifests and folder patterns given to :class:`~torch_eigview.datasets.manifest.ViewManifest`:
each must raise ValueError or TypeError naming the file and line (or the argument), the
constraint and the value; the formats spreadsheets and editors write (BOM, CRLF, quoted
commas, unicode names, extra columns) must read as the same views, and the good manifests
and patterns of ``GOOD`` as the views they list.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from torch_eigview.datasets.manifest import ViewManifest

from tests.adversarial import files, views
from tests.adversarial.harness import Case, Good, judge, outcome, params

HEAD = "path,object,azimuth\n"


def _read(content: str, encoding: str = "utf-8") -> object:
    """A case: ``ViewManifest.from_csv`` of m.csv holding ``content``."""
    return lambda t: ViewManifest.from_csv(views.csv(t, content, encoding=encoding))


def _read_bytes(content: bytes) -> object:
    def run(tmp: Path) -> object:
        views.manifest(tmp)
        (tmp / "m.csv").write_bytes(content)
        return ViewManifest.from_csv(tmp / "m.csv")

    return run


def _row_with(make: object, name: str = "odd.png") -> object:
    """A case: m.csv lists ``name`` (made by ``make(path)``) as a view."""

    def run(tmp: Path) -> object:
        views.manifest(tmp)
        make(tmp / name)  # type: ignore[operator]
        (tmp / "m.csv").write_text(f"{HEAD}egg/0.png,egg,0\n{name},odd,0\n")
        return ViewManifest.from_csv(tmp / "m.csv")

    return run


def _pattern(pattern: str, root: str = "") -> object:
    def run(tmp: Path) -> object:
        views.manifest(tmp)
        return ViewManifest.from_pattern(tmp / root, pattern)

    return run


CSV = [
    Case(
        "header-missing-azimuth",
        _read("path,object\negg/0.png,egg\n"),
        r"m\.csv line 1: .*missing \['azimuth'\]",
    ),
    Case(
        "header-duplicate-column",
        _read("path,object,azimuth,azimuth\negg/0.png,egg,0,10\n"),
        r"m\.csv line 1: .*column 'azimuth' (twice|more than once)",
    ),
    Case("header-case", _read("Path,Object,Azimuth\negg/0.png,egg,0\n"), r"m\.csv line 1: .*missing"),
    Case("header-only", _read(HEAD), r"m\.csv lists no view"),
    Case("empty-file", _read(""), r"m\.csv line 1: .*missing"),
    Case("blank-lines-only", _read("\n\n\n"), r"m\.csv line 1: .*missing"),
    Case("row-too-few-fields", _read(HEAD + "egg/0.png,egg\n"), r"m\.csv line 2: has 2 fields, the header 3"),
    Case(
        "row-too-many-fields",
        _read(HEAD + "egg/0.png,egg,0,5\n"),
        r"m\.csv line 2: has 4 fields, the header 3",
    ),
    Case(
        "azimuth-nan", _read(HEAD + "egg/0.png,egg,nan\n"), r"m\.csv line 2: azimuth='nan' must be a finite"
    ),
    Case(
        "azimuth-inf", _read(HEAD + "egg/0.png,egg,-inf\n"), r"m\.csv line 2: azimuth='-inf' must be a finite"
    ),
    Case(
        "azimuth-overflow",
        _read(HEAD + "egg/0.png,egg,1e400\n"),
        r"m\.csv line 2: azimuth='1e400' must be a finite",
    ),
    Case("azimuth-empty", _read(HEAD + "egg/0.png,egg,\n"), r"m\.csv line 2: azimuth='' must be a number"),
    Case(
        "azimuth-unit",
        _read(HEAD + "egg/0.png,egg,10deg\n"),
        r"m\.csv line 2: azimuth='10deg' must be a number",
    ),
    Case(
        "azimuth-huge",
        _read(HEAD + "egg/0.png,egg,1e300\n"),
        r"m\.csv line 2: azimuth='1e\+?300' must (lie in|be).*\[-?\d+",
    ),
    Case(
        "elevation-95",
        _read("path,object,azimuth,elevation\negg/0.png,egg,0,95\n"),
        r"m\.csv line 2: elevation='95' must lie in \[-90, 90\]",
    ),
    Case("object-empty", _read(HEAD + "egg/0.png,  ,0\n"), r"m\.csv line 2: object must be a non-empty name"),
    Case(
        "object-newline",
        _read(HEAD + 'egg/0.png,"egg\nfake line",0\n'),
        r"m\.csv line \d: object='egg\\nfake line' must not hold control characters",
    ),
    Case(
        "object-escape-sequence",
        _read(HEAD + "egg/0.png,\x1b[31mred,0\n"),
        r"m\.csv line 2: object='\\x1b\[31mred' must not hold control characters",
    ),
    Case("path-empty", _read(HEAD + ",egg,0\n"), r"m\.csv line 2: path must name an image file"),
    Case(
        "path-missing", _read(HEAD + "none.png,egg,0\n"), r"m\.csv line 2: image .*none\.png does not exist"
    ),
    Case("path-directory", _read(HEAD + "egg,egg,0\n"), r"m\.csv line 2: image .*egg is a directory"),
    Case("path-fifo", _row_with(files.fifo), r"m\.csv line 3: image .*odd\.png is a FIFO"),
    Case(
        "path-symlink-loop",
        _row_with(lambda p: os.symlink(p, p)),
        r"m\.csv line 3: image .*odd\.png cannot be used: Too many levels of symbolic links",
    ),
    Case("path-dev-zero", _read(HEAD + "/dev/zero,egg,0\n"), r"m\.csv line 2: image /dev/zero is a device"),
    Case(
        "mask-missing",
        _read("path,object,azimuth,mask\negg/0.png,egg,0,none.png\n"),
        r"m\.csv line 2: mask .*none\.png does not exist",
    ),
    Case(
        "mask-directory",
        _read("path,object,azimuth,mask\negg/0.png,egg,0,egg\n"),
        r"m\.csv line 2: mask .*egg is a directory",
    ),
    Case(
        "duplicate-view",
        _read(HEAD + "egg/0.png,egg,0\negg/10.png,egg,360\n"),
        r"m\.csv line 3: duplicates the view of .*m\.csv line 2",
    ),
    Case(
        "nul-byte", _read(HEAD + "egg/0.png,egg,0\x00\n"), r"m\.csv line 2: azimuth='0\\x00' must be a number"
    ),
    Case(
        "latin-1",
        _read(HEAD + "egg/0.png,caf\xe9,0\n", encoding="latin-1"),
        r"m\.csv line 2: is not UTF-8 text \(byte 0xe9\)",
    ),
    Case(
        "field-too-large",
        _read(HEAD + "egg/0.png," + "x" * 200_000 + ",0\n"),
        r"m\.csv line 2: cannot be parsed as CSV: field larger than field limit",
    ),
    Case(
        "unclosed-quote",
        _read(HEAD + 'egg/0.png,"egg,0\n'),
        r"m\.csv line \d: has 2 fields, the header 3 \(a quoted field runs on.*quote left open",
    ),
    Case("binary-file", _read_bytes(bytes(range(256)) * 4), r"m\.csv line \d+: is not UTF-8 text"),
    Case("path-int", lambda t: ViewManifest.from_csv(3), r"path must be a str or a path, got int"),  # type: ignore[arg-type]
    Case(
        "path-directory-itself",
        lambda t: ViewManifest.from_csv(t),
        r"manifest .* is a directory, not a regular file",
    ),
    Case(
        "skipped-not-a-list",
        lambda t: ViewManifest.from_csv(views.csv(t, HEAD + "none.png,egg,0\n"), skipped="x"),  # type: ignore[arg-type]
        r"skipped must be a list or None, got str",
    ),
    Case(
        "skipped-all-bad",
        lambda t: ViewManifest.from_csv(views.csv(t, HEAD + "none.png,egg,0\n"), skipped=[]),
        r"m\.csv lists no view, only bad lines: .*m\.csv line 2: image .*none\.png does not exist",
    ),
]

PATTERN = [
    Case(
        "pattern-no-azimuth", _pattern("{object}/x.png"), r"pattern='\{object\}/x\.png' must name the fields"
    ),
    Case(
        "pattern-unknown-field",
        _pattern("{object}/{angle}.png"),
        r"pattern='\{object\}/\{angle\}\.png': unknown field \{angle\}",
    ),
    Case(
        "pattern-stray-brace",
        _pattern("{object}/{azimuth}}.png"),
        r"pattern='\{object\}/\{azimuth\}\}\.png' holds an unmatched brace",
    ),
    Case(
        "pattern-absolute",
        _pattern("/{object}/{azimuth}.png"),
        r"pattern='/\{object\}/\{azimuth\}\.png' must be a path relative to the root",
    ),
    Case(
        "pattern-escapes-root",
        _pattern("../{object}/{azimuth}.png"),
        r"pattern='\.\./\{object\}/\{azimuth\}\.png' must be a path relative to the root",
    ),
    Case(
        "pattern-no-match",
        _pattern("{object}/{azimuth}.jpg"),
        r"root=.* holds no file that matches pattern='\{object\}/\{azimuth\}\.jpg'",
    ),
    Case("pattern-not-str", lambda t: ViewManifest.from_pattern(t, 5), r"pattern must be a str, got int"),  # type: ignore[arg-type]
    Case("pattern-empty", _pattern(""), r"pattern='' must name the fields"),
    Case(
        "root-missing",
        _pattern("{object}/{azimuth}.png", root="none"),
        r"root=.*none' must be an existing directory",
    ),
    Case(
        "root-a-file",
        _pattern("{object}/{azimuth}.png", root="views.csv"),
        r"root=.*views\.csv' must be an existing directory",
    ),
    Case(
        "pattern-matches-a-fifo",
        lambda t: (
            views.manifest(t),
            files.fifo(t / "egg" / "30.png"),
            ViewManifest.from_pattern(t, "{object}/{azimuth}.png"),
        ),
        r"egg/30\.png is a FIFO .*not a regular file",
    ),
    Case(
        "pattern-elevation-95",
        lambda t: (
            views.manifest(t),
            files.image(t, "egg-95-0.png"),
            ViewManifest.from_pattern(t, "{object}-{elevation}-{azimuth}.png"),
        ),
        r"egg-95-0\.png: elevation='95' must lie in \[-90, 90\]",
    ),
]

CASES = CSV + PATTERN

#: The views :func:`views.manifest` lists: (object, azimuth, file), in its order.
LISTED = [(o, float(a), f"{o}/{a}.png") for o in views.OBJECTS for a in views.AZIMUTHS]


def _views(manifest: ViewManifest, tmp: Path) -> list[tuple[str, float, str]]:
    return [(e.object, e.azimuth, e.path.relative_to(tmp).as_posix()) for e in manifest]


def _lists_the_views(manifest: ViewManifest, tmp: Path) -> bool:
    assert sorted(_views(manifest, tmp)) == LISTED, _views(manifest, tmp)
    assert all(math.isnan(e.elevation) and e.mask is None for e in manifest), list(manifest)
    return True


def _with_columns(tmp: Path) -> ViewManifest:
    """A manifest with the optional elevation and mask columns."""
    views.manifest(tmp)
    views.png(tmp / "mask.png", views._rendered()["egg", 0])
    return ViewManifest.from_csv(
        _write(tmp, "path,object,azimuth,elevation,mask\negg/0.png,egg,350,-30,mask.png\n")
    )


def _columns_read(manifest: ViewManifest, tmp: Path) -> bool:
    (entry,) = list(manifest)
    assert (entry.object, entry.azimuth, entry.elevation) == ("egg", 350.0, -30.0), entry
    assert entry.mask == tmp / "mask.png", entry
    return True


def _skipping(tmp: Path) -> tuple[ViewManifest, list[str]]:
    """The manifest plus one line naming a missing image, read with ``skipped``."""
    skipped: list[str] = []
    return ViewManifest.from_csv(views.manifest(tmp, "none.png,egg,30\n"), skipped=skipped), skipped


def _skipped_one(out: tuple[ViewManifest, list[str]], tmp: Path) -> bool:
    manifest, skipped = out
    assert _lists_the_views(manifest, tmp)
    assert len(skipped) == 1 and "views.csv line 8: image" in skipped[0] and "does not exist" in skipped[0], (
        skipped
    )
    return True


GOOD = [
    Good("manifest", lambda t: ViewManifest.from_csv(views.manifest(t)), _lists_the_views),
    Good(
        "pattern",
        lambda t: (views.manifest(t), ViewManifest.from_pattern(t, "{object}/{azimuth}.png"))[1],
        _lists_the_views,
    ),
    Good("elevation-and-mask-columns", _with_columns, _columns_read),
    Good("skipped-bad-line", _skipping, _skipped_one),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_manifest_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what


@pytest.mark.parametrize("case", params(GOOD))
def test_good_manifest_is_answered_right(case: Good, tmp_path: Path) -> None:
    kind, what = judge(case, tmp_path)
    assert kind == "right", what


@pytest.mark.parametrize(
    ("content", "encoding"),
    [
        ("\ufeffpath,object,azimuth\r\negg/0.png,egg,0\r\nhead/0.png,head,10\r\n", "utf-8"),  # BOM, CRLF
        (
            'path,object,azimuth,note\n"egg/0.png",egg,0,"a, b"\n"head/0.png",head,10,\n',
            "utf-8",
        ),  # quotes, extra
        ("object,azimuth,path\negg,0,egg/0.png\n\nhead,10.0,head/0.png\n", "utf-8"),  # order, blank line
    ],
    ids=["bom-crlf", "quoted-extra-column", "column-order-blank-line"],
)
def test_spreadsheet_formats_read_the_same_views(tmp_path: Path, content: str, encoding: str) -> None:
    manifest = ViewManifest.from_csv(views.csv(tmp_path, content, encoding=encoding))
    assert [(e.object, e.azimuth, e.path.name) for e in manifest] == [
        ("egg", 0.0, "0.png"),
        ("head", 10.0, "0.png"),
    ]
    assert [e.path.parent.name for e in manifest] == ["egg", "head"]


def test_unicode_names_and_paths_are_kept(tmp_path: Path) -> None:
    views.manifest(tmp_path)
    (tmp_path / "egg" / "0.png").rename(tmp_path / "egg" / "tête 0.png")
    content = HEAD + '"egg/tête 0.png",Ölkännchen 茶壺,0\n'
    manifest = ViewManifest.from_csv(_write(tmp_path, content))
    assert manifest.objects == ["Ölkännchen 茶壺"]
    assert manifest[0].path.name == "tête 0.png"


def _write(tmp: Path, content: str) -> Path:
    path = tmp / "m.csv"
    path.write_text(content, encoding="utf-8")
    return path
