"""The result record each diagnosis of ``examples/diagnostics`` writes, and the flags they share.

A record is one JSON file per table, ``examples/diagnostics/results/<name>.json`` by
default, in the format ``docs/make_pages.py`` reads (its docstring documents it): a title,
the command line that reproduces it, :func:`torch_eigview.environment_info`, the tables and
any raw figures. ``python docs/make_pages.py`` turns the records into ``docs/results.md``.
(``examples/paper/record.py`` is the same for the paper's figures: each folder's scripts
import their own.)
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from torch_eigview import CoilFolder, environment_info
from torch_eigview.datasets import find_coil_root, parse_object_spec
from torch_eigview.files import check_output_path, write_json

ROOT = Path(__file__).resolve().parents[2]
RESULTS = Path(__file__).resolve().parent / "results"


def add_root_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--root",
        help="the COIL-20 folder itself (default: coil-20-proc/ in the data home, $TORCH_EIGVIEW_DATA or "
        "its default); in a checkout beside the project's data: ../shared/data/coil-20-proc",
    )


def add_objects_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--objects", type=objects_arg, default=None, help="e.g. 1-20 or 1,3,5-7 (default: all)"
    )


def add_record_flag(parser: argparse.ArgumentParser, name: str) -> None:
    """``--record PATH``: where the record goes (default ``results/<name>.json``; '' for none)."""
    parser.add_argument(
        "--record",
        default=str(RESULTS / f"{name}.json"),
        help=f"the JSON result record to write (default examples/diagnostics/results/{name}.json; '' for none)",
    )


def add_centers_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--centers", type=float, nargs="+", default=[0.0, 90.0, 180.0, 270.0])


def objects_arg(text: str) -> list[int]:
    """An argparse type: an object selection such as ``1-20`` or ``1,3,5-7``."""
    try:
        return parse_object_spec(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def coil_folder(parser: argparse.ArgumentParser, root: str | None) -> CoilFolder:
    """The COIL folder of ``--root`` (or the default one); a missing folder exits 2 naming
    where the images go, not with a traceback."""
    try:
        return CoilFolder(find_coil_root(root))
    except ValueError as exc:
        parser.error(f"{exc} This script takes the folder as --root DIR.")


def check_record(parser: argparse.ArgumentParser, path: str) -> None:
    """An unwritable ``--record`` exits 2 before any work (the default's folder is made)."""
    if path:
        if Path(path).resolve().parent == RESULTS:
            RESULTS.mkdir(exist_ok=True)
        try:
            check_output_path(path, "--record")
        except (TypeError, ValueError) as exc:
            parser.error(str(exc))


def command_line(script: str, argv: Sequence[str] | None) -> str:
    """``python <script relative to the repository root> <argv>``: the record's command."""
    path = Path(script).resolve()
    shown = path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else str(path)
    return shlex.join(["python", shown, *(sys.argv[1:] if argv is None else argv)])


def cell(value: Any) -> Any:
    """A table cell: NaN (no recognized view, no paper figure) becomes null, shown as a dash."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


def table(caption: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> dict[str, Any]:
    return {"caption": caption, "columns": list(columns), "rows": [[cell(v) for v in row] for row in rows]}


def text(tab: dict[str, Any]) -> str:
    """A :func:`table` as aligned text for the terminal: its caption, then the columns."""

    def shown(value: Any) -> str:
        if value is None:
            return "-"
        if isinstance(value, float):
            return f"{value:.4g}" if 0 < abs(value) < 1e-2 else f"{value:.2f}"
        return str(value)

    cells = [[str(c) for c in tab["columns"]], *([shown(v) for v in row] for row in tab["rows"])]
    widths = [max(len(row[i]) for row in cells) for i in range(len(cells[0]))]
    lines = ["  ".join(v.rjust(w) for v, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join([tab["caption"], *lines])


def write_record(
    path: str,
    *,
    title: str,
    command: str,
    tables: list[dict[str, Any]],
    notes: str | None = None,
    **raw: Any,
) -> None:
    """Writes the record to ``path`` (nothing for ''); ``raw`` holds the figures behind the tables."""
    if not path:
        return
    record: dict[str, Any] = {
        "title": title,
        "page": "results",
        "command": command,
        "environment": environment_info(),
        "tables": tables,
    }
    if notes:
        record["notes"] = notes
    record.update(raw)
    write_json(path, record, default=str)
    print(f"record written to {path}")
