"""The result record every benchmark writes, and the options every benchmark shares.

A record is one JSON file, ``benchmarks/results/<name>.json`` for ``bench_<name>.py`` by
default, in the format ``docs/make_pages.py`` renders into ``docs/benchmarks.md``::

    {"title": ..., "page": "benchmarks", "command": "python benchmarks/bench_<name>.py ...",
     "environment": torch_eigview.environment_info(),
     "tables": [{"caption": ..., "columns": [...], "rows": [[...], ...]}],
     "notes": "optional Markdown", "raw": {the figures as measured}}

The command is the one that reproduces the record: the script's path from the repository
root, the arguments it was given, and the thread variables that were set. A ``--quick``
run is a check that the script works, not a figure to publish: it writes a record only
where ``--out`` names a file.
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from torch_eigview import environment_info
from torch_eigview.files import check_output_path, write_json

__all__ = [
    "RESULTS",
    "add_threads",
    "check_out",
    "command_line",
    "format_table",
    "parser",
    "record_path",
    "table",
    "write_record",
]

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).resolve().parent / "results"
# Variables that change what a run measures; the command line carries them when set.
_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _name(script: str) -> str:
    """``warp`` for ``.../bench_warp.py``: its record is ``results/warp.json``."""
    return Path(script).stem.removeprefix("bench_")


def parser(script: str, doc: str, quick: str) -> argparse.ArgumentParser:
    """The script's parser with the shared ``--quick`` and ``--out`` options.

    Args:
        script: the script's ``__file__``.
        doc: its module docstring; the first line is the description.
        quick: what ``--quick`` shrinks the run to (its help).
    """
    prog = f"python {Path(script).resolve().relative_to(ROOT)}"
    p = argparse.ArgumentParser(prog=prog, description=doc.strip().splitlines()[0])
    p.add_argument("--quick", action="store_true", help=f"{quick}: checks that the script runs")
    p.add_argument(
        "--out",
        default=None,
        metavar="FILE",
        help=f"the result record (default benchmarks/results/{_name(script)}.json; a --quick run "
        "writes one only where --out names it; '' for none)",
    )
    return p


def _threads_arg(text: str) -> int:
    """``--threads N``: an int >= 1 (argparse type)."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"--threads must be an integer >= 1, got {text!r}")
    return value


def add_threads(p: argparse.ArgumentParser) -> None:
    """``--threads N``: the torch threads of the run, under :func:`torch_eigview.scale.threads`."""
    p.add_argument(
        "--threads",
        type=_threads_arg,
        default=None,
        metavar="N",
        help="torch intra-op threads (default: the eigview commands' policy, one thread, and the "
        "CPUs other processes leave idle for a large eigen step)",
    )


def record_path(args: argparse.Namespace, script: str) -> Path | None:
    """Where the record goes: ``--out``, else the results folder, none for ``--quick`` or ``''``."""
    if args.out is None:
        return None if args.quick else RESULTS / f"{_name(script)}.json"
    return Path(args.out) if args.out else None


def check_out(p: argparse.ArgumentParser, path: Path | None) -> None:
    """Exits 2 with the parser's message when the record could not be written, before any work."""
    if path is None:
        return
    if path.parent == RESULTS:
        RESULTS.mkdir(exist_ok=True)
    try:
        check_output_path(path, "--out")
    except ValueError as exc:
        p.error(str(exc))


def command_line(
    script: str, argv: Sequence[str], launcher: Sequence[str] = ("python",), *, thread_vars: bool = True
) -> str:
    """The shell command that reproduces a run: the thread variables that are set (unless
    ``thread_vars`` is False: a launcher such as torchrun sets them itself), ``launcher``,
    the script's path from the repository root, and ``argv``."""
    env = [f"{var}={os.environ[var]}" for var in _THREAD_VARS if thread_vars and os.environ.get(var)]
    where = Path(script).resolve().relative_to(ROOT)
    return shlex.join([*env, *launcher, str(where), *argv])


def table(caption: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> dict[str, Any]:
    """One table of a record; None marks a figure that was not measured."""
    for text in (*columns, *(v for row in rows for v in row if isinstance(v, str))):
        if "|" in text:  # it would split a cell of the Markdown table make_pages renders
            raise ValueError(f"a column or cell of {caption!r} holds '|': {text!r}")
    for row in rows:
        if len(row) != len(columns):
            raise ValueError(f"a row of {caption!r} has {len(row)} cells for {len(columns)} columns")
    return {"caption": caption, "columns": list(columns), "rows": [list(r) for r in rows]}


def _cell(value: Any) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.0f}" if 1e3 <= abs(value) < 1e15 else f"{value:.4g}"
    return str(value)


def format_table(t: dict[str, Any]) -> str:
    """A table as aligned text, for the script's own output."""
    cells = [t["columns"], *[[_cell(v) for v in row] for row in t["rows"]]]
    widths = [max(len(str(row[i])) for row in cells) for i in range(len(t["columns"]))]
    lines = [f"== {t['caption']}"]
    lines += ["  ".join(str(c).rjust(w) for c, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join(lines)


def _plain(value: Any) -> Any:
    """JSON-ready figures: numpy and torch scalars as Python numbers, NaN and ±inf as None."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # numpy or torch scalar
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def write_record(
    path: Path | None,
    *,
    title: str,
    command: str,
    tables: Sequence[dict[str, Any]],
    notes: str | None = None,
    raw: Any = None,
) -> None:
    """Writes the record to ``path`` (atomically) and says so; nothing for None.

    Args:
        path: from :func:`record_path`.
        title: the section title on the benchmarks page.
        command: from :func:`command_line`.
        tables: from :func:`table`.
        notes: Markdown printed under the tables.
        raw: every figure as measured (JSON-ready after numpy/torch scalars become numbers).
    """
    if path is None:
        return
    record: dict[str, Any] = {
        "title": title,
        "page": "benchmarks",
        "command": command,
        "environment": environment_info(),
        "tables": _plain(list(tables)),
    }
    if notes:
        record["notes"] = notes
    if raw is not None:
        record["raw"] = _plain(raw)
    write_json(path, record, allow_nan=False, ensure_ascii=False)
    print(f"wrote {path}")
