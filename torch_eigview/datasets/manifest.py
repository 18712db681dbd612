"""View manifests: which image shows which object at which angles, from a CSV file, a folder pattern or COIL.

A manifest is a CSV file with a header and the columns ``path,object,azimuth`` (degrees),
optionally ``elevation`` (degrees) and ``mask`` (a mask image, non-zero is object); other
columns are ignored. Relative paths resolve against the manifest's folder. For example::

    path,object,azimuth,mask
    cup/000.png,cup,0,cup/000-mask.png
    cup/010.png,cup,10,cup/010-mask.png

A folder pattern such as ``"{object}/{object}-{elevation}-{azimuth}.png"`` takes the place of
a manifest: the fields are parsed from the paths of the files under a root folder. Every
file is checked when the manifest is made; the pixels are read by
:class:`~torch_eigview.datasets.image_views.ViewDataset`.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.io.images import check_regular_file
from torch_eigview.parse import parse_float

__all__ = ["ViewEntry", "ViewManifest"]

_REQUIRED = ("path", "object", "azimuth")
_FIELDS = ("object", "azimuth", "elevation")
_NUMBER = r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)"
_FIELD_RE = re.compile(r"\{([^{}]*)\}")
# Degrees: past this an angle modulo 360 keeps no precision that means anything (float64
# resolves 1e6 degrees to 1e-10); an unwrapped turntable angle of a few turns is far below it.
_MAX_ANGLE = 1e6
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


@dataclass(frozen=True)
class ViewEntry:
    """One view of a manifest.

    Attributes:
        path: The image file.
        object: The object's name.
        azimuth: Turntable angle in degrees, in ``[0, 360)`` (the given angle modulo 360).
        elevation: Camera elevation in degrees, ``nan`` when the manifest has none.
        mask: The mask image (non-zero is object), or None.
        source: Where the view was listed, for error messages: ``"views.csv line 7"`` or
            the image path for a folder pattern.
    """

    path: Path
    object: str
    azimuth: float
    elevation: float
    mask: Path | None
    source: str


def _angle(text: str, column: str, where: str, lo: float | None = None, hi: float | None = None) -> float:
    """A finite angle in degrees parsed from ``text``; a ValueError naming ``where`` otherwise."""
    try:
        # Strictly decimal: float() would read "1_0" as 10 and "١٠" as 10, both more likely typos.
        value = parse_float(text.strip(), column)
    except ValueError:
        raise ValueError(
            f"{where}: {column}={text!r} must be a number of degrees in decimal digits (such as 10 or -2.5)"
        ) from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: {column}={text!r} must be a finite number of degrees")
    lo, hi = (-_MAX_ANGLE, _MAX_ANGLE) if lo is None or hi is None else (lo, hi)
    if not lo <= value <= hi:
        raise ValueError(f"{where}: {column}={text!r} must lie in [{lo:g}, {hi:g}] degrees")
    return value


def _entry(
    path: Path, obj: str, azimuth: str, elevation: str | None, mask: Path | None, where: str
) -> ViewEntry:
    """A checked entry: the files exist and are regular, the object is named, the angles are numbers."""
    if not obj.strip():
        raise ValueError(f"{where}: object must be a non-empty name, got {obj!r}")
    if _CONTROL.search(obj):  # a newline or an ANSI escape would forge lines of a report
        raise ValueError(f"{where}: object={obj!r} must not hold control characters")
    az = _angle(azimuth, "azimuth", where) % 360.0
    el = (
        math.nan
        if elevation is None or elevation.strip() == ""
        else _angle(elevation, "elevation", where, -90, 90)
    )
    for what, file in (("image", path), ("mask", mask)):
        if file is not None:
            try:
                check_regular_file(file, what)
            except ValueError as exc:
                raise ValueError(f"{where}: {exc}") from None
    return ViewEntry(path=path, object=obj.strip(), azimuth=az, elevation=el, mask=mask, source=where)


def _csv_entries(manifest: Path, skipped: list[str] | None = None) -> list[ViewEntry]:
    """The entries of a CSV manifest, each checked; errors name the file and the line.

    With ``skipped``, a bad line's error message is appended to it and the line left out
    (a bad header still raises)."""
    base = manifest.parent
    try:
        handle = manifest.open(newline="", encoding="utf-8-sig")  # utf-8-sig: spreadsheets write a BOM
    except OSError as exc:
        raise ValueError(f"manifest {manifest} cannot be read: {exc.strerror or exc}") from None
    with handle:
        reader = csv.reader(handle)
        try:
            return _read_rows(reader, manifest, base, skipped)
        except UnicodeDecodeError:
            raise ValueError(_not_utf8(manifest)) from None
        except csv.Error as exc:  # a field over csv's size limit, a NUL byte, a bad quote
            raise ValueError(f"{manifest} line {reader.line_num}: cannot be parsed as CSV: {exc}") from None


def _not_utf8(manifest: Path) -> str:
    """The message for a manifest that is not UTF-8: the line and the first bad byte."""
    data = manifest.read_bytes()
    try:
        data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        return f"{manifest} line {line}: is not UTF-8 text (byte 0x{data[exc.start]:02x}); save it as UTF-8"
    return f"{manifest} changed while it was read"  # decoded in one piece, it is UTF-8


def _read_rows(
    reader: Iterator[list[str]], manifest: Path, base: Path, skipped: list[str] | None
) -> list[ViewEntry]:
    """The checked entries of a CSV reader's rows, the header first."""
    header = [h.strip() for h in next(reader, [])]
    missing = [c for c in _REQUIRED if c not in header]
    if missing:
        raise ValueError(
            f"{manifest} line 1: the header must hold the columns {', '.join(_REQUIRED)} "
            f"(optional: elevation, mask), missing {missing}; got {header}"
        )
    twice = sorted({h for h in header if h and header.count(h) > 1})
    if twice:
        raise ValueError(f"{manifest} line 1: the header names the column {twice[0]!r} twice; got {header}")
    col = {name: header.index(name) for name in (*_REQUIRED, "elevation", "mask") if name in header}
    entries = []
    for row in reader:
        where = f"{manifest} line {reader.line_num}"  # type: ignore[attr-defined]
        if not any(cell.strip() for cell in row):
            continue  # blank lines separate groups in hand-written manifests
        try:
            entries.append(_row_entry(header, row, col, base, where))
        except ValueError as exc:
            if skipped is None:
                raise
            skipped.append(str(exc))
    return entries


def _row_entry(header: list[str], row: list[str], col: dict[str, int], base: Path, where: str) -> ViewEntry:
    """The checked entry of one CSV row."""
    if len(row) != len(header):
        spans = any("\n" in cell for cell in row)  # a quote that is never closed takes in the lines after it
        hint = " (a quoted field runs on over several lines: is a quote left open?)" if spans else ""
        raise ValueError(f"{where}: has {len(row)} fields, the header {len(header)}{hint}")
    cells = {name: row[i].strip() for name, i in col.items()}
    if not cells["path"]:
        raise ValueError(f"{where}: path must name an image file, got an empty field")
    mask = base / cells["mask"] if cells.get("mask") else None
    return _entry(
        base / cells["path"], cells["object"], cells["azimuth"], cells.get("elevation"), mask, where
    )


def _literal(pattern: str, text: str) -> str:
    """The escaped literal text between two fields; a stray brace is an error."""
    if "{" in text or "}" in text:
        raise ValueError(f"pattern={pattern!r} holds an unmatched brace in {text!r}")
    return re.escape(text)


def _pattern_regex(pattern: str) -> re.Pattern[str]:
    """The regular expression of a folder pattern; the second ``{object}`` must repeat the first."""
    parts, seen, pos = [], set(), 0
    for m in _FIELD_RE.finditer(pattern):
        name = m.group(1)
        if name not in _FIELDS:
            raise ValueError(f"pattern={pattern!r}: unknown field {{{name}}} (fields: {', '.join(_FIELDS)})")
        parts.append(_literal(pattern, pattern[pos : m.start()]))
        if name in seen:
            parts.append(f"(?P={name})")
        else:
            parts.append(f"(?P<{name}>[^/]+?)" if name == "object" else f"(?P<{name}>{_NUMBER})")
            seen.add(name)
        pos = m.end()
    parts.append(_literal(pattern, pattern[pos:]))
    if not {"object", "azimuth"} <= seen:
        raise ValueError(f"pattern={pattern!r} must name the fields {{object}} and {{azimuth}}")
    if pattern.startswith("/") or ".." in pattern.split("/"):
        raise ValueError(f"pattern={pattern!r} must be a path relative to the root, inside it")
    return re.compile("".join(parts))


def _pattern_entries(root: Path, pattern: str) -> list[ViewEntry]:
    """The files under ``root`` whose relative path matches ``pattern``, in sorted order."""
    regex = _pattern_regex(pattern)
    entries = []
    for folder, dirs, files in os.walk(root):
        dirs.sort()
        for name in sorted(files):
            path = Path(folder) / name
            m = regex.fullmatch(path.relative_to(root).as_posix())
            if m is not None:
                fields = m.groupdict()
                entries.append(
                    _entry(
                        path, fields["object"], fields["azimuth"], fields.get("elevation"), None, str(path)
                    )
                )
    if not entries:
        raise ValueError(f"root={str(root)!r} holds no file that matches pattern={pattern!r}")
    return entries


class ViewManifest:
    """Views of objects with their angles (and masks): the input of :class:`ViewDataset`.

    Made with :meth:`from_csv`, :meth:`from_pattern` or :meth:`from_coil`, or from a list
    of :class:`ViewEntry`. No two entries may show the same object at the same azimuth
    (modulo 360) and elevation.

    Args:
        entries: The views, in their listed order.
        name: What the views came from, for ``repr`` and errors.
        skipped: None (a bad entry raises), or a list that collects the error message of
            each bad entry, which is then left out (``eigview evaluate`` goes on past a bad
            row); here, the second of two entries that name the same view.

    Raises:
        ValueError: No entry, or two entries name the same view (the message names both).
    """

    def __init__(
        self, entries: Sequence[ViewEntry], name: str = "manifest", *, skipped: list[str] | None = None
    ) -> None:
        entries = list(entries)
        if not entries and skipped:  # the cause is the bad lines, not an empty file
            more = f" (and {len(skipped) - 1} more bad line(s))" if len(skipped) > 1 else ""
            raise ValueError(f"{name} lists no view, only bad lines: {skipped[0]}{more}")
        if not entries:
            raise ValueError(f"{name} lists no view")
        if not all(isinstance(e, ViewEntry) for e in entries):
            raise TypeError("entries must all be ViewEntry")
        seen: dict[tuple[str, float, float | None], ViewEntry] = {}
        kept = []
        for e in entries:
            key = (e.object, e.azimuth, None if math.isnan(e.elevation) else e.elevation)
            if key in seen:
                message = (
                    f"{e.source}: duplicates the view of {seen[key].source} (object {e.object!r}, "
                    f"azimuth {e.azimuth:g}, elevation {e.elevation:g}): {e.path} and {seen[key].path}"
                )
                if skipped is None:
                    raise ValueError(message)
                skipped.append(message)
                continue
            seen[key] = e
            kept.append(e)
        self.entries: list[ViewEntry] = kept
        self.name = name

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str], *, skipped: list[str] | None = None) -> ViewManifest:
        """Reads a CSV manifest (see the module docstring).

        Args:
            path: The CSV file.
            skipped: None (a bad line raises), or a list that collects the error of each
                bad line (naming the manifest and the line), which is left out.

        Raises:
            TypeError: ``path`` is not a path.
            ValueError: The file cannot be read, a column is missing, or a line names a
                missing file, a non-numeric angle or a duplicate view; the message names
                the manifest and the line.
        """
        if not isinstance(path, (str, os.PathLike)):
            raise TypeError(f"path must be a str or a path, got {type(path).__name__}")
        if skipped is not None and not isinstance(skipped, list):
            raise TypeError(f"skipped must be a list or None, got {type(skipped).__name__}")
        manifest = Path(path)
        check_regular_file(manifest, "manifest")
        return cls(_csv_entries(manifest, skipped), name=str(manifest), skipped=skipped)

    @classmethod
    def from_pattern(cls, root: str | os.PathLike[str], pattern: str) -> ViewManifest:
        """The files under ``root`` whose path relative to it matches ``pattern``.

        Args:
            root: The folder searched (recursively).
            pattern: A relative path with the fields ``{object}`` (any text without ``/``;
                repeated, it must repeat the same text), ``{azimuth}`` and optionally
                ``{elevation}`` (numbers of degrees), e.g. ``"{object}/{object}-{azimuth}.png"``.
                Files that do not match are ignored.

        Raises:
            TypeError: ``root`` is not a path or ``pattern`` not a str.
            ValueError: ``root`` is not a folder, the pattern is malformed or lacks
                ``{object}`` or ``{azimuth}``, no file matches, or two files name one view.
        """
        if not isinstance(root, (str, os.PathLike)):
            raise TypeError(f"root must be a str or a path, got {type(root).__name__}")
        if not isinstance(pattern, str):
            raise TypeError(f"pattern must be a str, got {type(pattern).__name__}")
        folder = Path(root)
        if not folder.is_dir():
            raise ValueError(f"root={str(folder)!r} must be an existing directory")
        return cls(_pattern_entries(folder, pattern), name=f"{folder}/{pattern}")

    @classmethod
    def from_coil(cls, root: str | os.PathLike[str], *, pose_unit: str = "auto") -> ViewManifest:
        """A manifest of a COIL folder (``obj{O}__{P}.png``), parsed by :class:`CoilFolder`.

        The objects are named ``str(O)``; the azimuths are :class:`CoilFolder`'s (``5·P``
        degrees for COIL-20 indices, ``P`` for COIL-100), elevation ``nan``, no mask.
        """
        coil = CoilFolder(root, pose_unit=pose_unit)
        entries = [
            ViewEntry(
                path=coil.path(o, deg),
                object=str(o),
                azimuth=deg,
                elevation=math.nan,
                mask=None,
                source=str(coil.path(o, deg)),
            )
            for o in coil.objects
            for deg in coil.poses(o)
        ]
        return cls(entries, name=str(coil.root))

    @property
    def objects(self) -> list[str]:
        """The object names, in the order of their first view."""
        return list(dict.fromkeys(e.object for e in self.entries))

    def views(self, obj: str) -> list[ViewEntry]:
        """The views of object ``obj``, sorted by azimuth (then elevation)."""
        views = [e for e in self.entries if e.object == obj]
        if not views:
            raise ValueError(f"object={obj!r} is not in {self.name} (objects: {self.objects[:10]})")
        return sorted(views, key=lambda e: (e.azimuth, -math.inf if math.isnan(e.elevation) else e.elevation))

    def __len__(self) -> int:
        return len(self.entries)

    def __getitem__(self, index: int) -> ViewEntry:
        return self.entries[index]

    def __iter__(self) -> Iterator[ViewEntry]:
        return iter(self.entries)

    def __repr__(self) -> str:
        return f"ViewManifest({self.name!r}, objects={len(self.objects)}, views={len(self)})"
