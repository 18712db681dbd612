"""The result record: its format is what ``docs/make_pages.py`` renders, its path and command."""

from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest
import torch

from benchmarks import _record
from benchmarks._record import RESULTS, command_line, format_table, parser, record_path, table, write_record

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = str(ROOT / "benchmarks" / "bench_example.py")  # a name: the helpers never open it


def make_pages() -> ModuleType:
    spec = importlib.util.spec_from_file_location("make_pages", ROOT / "docs" / "make_pages.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def check_record(path: Path) -> dict[str, Any]:
    """A record as ``docs/make_pages.py`` reads it: its keys, and its page renders."""
    record = json.loads(path.read_text(encoding="utf-8"))
    for key in ("title", "page", "command", "environment", "tables"):
        assert key in record, key
    assert record["page"] == "benchmarks" and record["command"].startswith(
        ("python benchmarks/", "torchrun ")
    )
    assert {"date", "packages", "machine"} <= set(record["environment"])
    for t in record["tables"]:
        assert t["rows"] and all(len(row) == len(t["columns"]) for row in t["rows"])
    pages = make_pages()
    text = pages.render("benchmarks", [(ROOT / "benchmarks" / "results" / path.name, record)])
    assert f"## {record['title']}" in text and record["tables"][0]["caption"] in text
    return record


def test_record_is_what_make_pages_renders(tmp_path: Path) -> None:
    t = table("ratios", ["name", "seconds", "× ref"], [["ours", 0.5, 1.0], ["theirs", np.float32(2.0), None]])
    path = tmp_path / "example.json"
    write_record(
        path,
        title="Example",
        command="python benchmarks/bench_example.py --quick",
        tables=[t],
        notes="a note",
        raw={"inf": float("inf"), "tensor": torch.tensor(3.0), "n": np.int64(4)},
    )
    record = check_record(path)
    assert record["raw"] == {"inf": None, "tensor": 3.0, "n": 4}
    assert record["tables"][0]["rows"][1] == ["theirs", 2.0, None] and record["notes"] == "a note"


def test_no_path_writes_nothing(tmp_path: Path) -> None:
    write_record(None, title="x", command="python x", tables=[])
    assert not list(tmp_path.iterdir())


def test_a_row_must_fill_the_columns() -> None:
    with pytest.raises(ValueError, match=r"a row of 'c' has 1 cells for 2 columns"):
        table("c", ["a", "b"], [[1]])
    with pytest.raises(ValueError, match=r"a column or cell of 'c' holds '\|': 'max \|x\|'"):
        table("c", ["max |x|"], [[1]])


def test_format_table_aligns_and_marks_missing_figures() -> None:
    text = format_table(table("caption", ["a", "long name"], [[1.23456, None], [12345.6, "x"]]))
    lines = text.splitlines()
    assert lines[0] == "== caption" and len({len(line) for line in lines[1:]}) == 1
    assert "1.235" in text and "12346" in text and "–" in text


def _args(*argv: str) -> argparse.Namespace:
    return parser(SCRIPT, "Doc line.\n\nMore.", "small").parse_args(list(argv))


def test_record_path_default_quick_and_none() -> None:
    assert record_path(_args(), SCRIPT) == RESULTS / "example.json"
    assert record_path(_args("--quick"), SCRIPT) is None  # a check, not a figure to publish
    assert record_path(_args("--quick", "--out", "r.json"), SCRIPT) == Path("r.json")
    assert record_path(_args("--out", ""), SCRIPT) is None


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda tmp: tmp, "is a directory"),
        (lambda tmp: tmp / "missing" / "r.json", "does not exist"),
    ],
    ids=["directory", "missing-folder"],
)
def test_a_bad_out_stops_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], make: object, message: str
) -> None:
    p = parser(SCRIPT, "Doc.", "small")
    with pytest.raises(SystemExit) as info:
        _record.check_out(p, make(tmp_path))  # type: ignore[operator]
    err = capsys.readouterr().err
    assert info.value.code == 2 and "python benchmarks/bench_example.py: error: " in err and message in err


def test_command_line_reproduces_the_run(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert command_line(SCRIPT, ["--out", "a b.json"]) == (
        "OMP_NUM_THREADS=1 python benchmarks/bench_example.py --out 'a b.json'"
    )
    launcher = ("torchrun", "--nproc_per_node", "2")
    assert command_line(SCRIPT, [], launcher, thread_vars=False) == (
        "torchrun --nproc_per_node 2 benchmarks/bench_example.py"
    )


def test_threads_must_be_a_positive_integer(capsys: pytest.CaptureFixture[str]) -> None:
    p = parser(SCRIPT, "Doc.", "small")
    _record.add_threads(p)
    assert p.parse_args(["--threads", "2"]).threads == 2
    for bad in ("0", "-1", "two"):
        with pytest.raises(SystemExit):
            p.parse_args(["--threads", bad])
        assert f"--threads must be an integer >= 1, got {bad!r}" in capsys.readouterr().err
