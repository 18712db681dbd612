"""The rejection diagnosis (``examples/diagnostics/rejection_split.py``): its ROC reading on
scores whose answer is known, its record on a small COIL-20 split, and its bad arguments."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from rejection_split import main, roc_at


def test_roc_reads_the_most_unknown_rejected_within_each_known_fraction() -> None:
    known = torch.arange(1.0, 101.0)  # a limit at c rejects the known scores above c
    unknown = torch.tensor([50.0, 99.5, 100.5, 200.0])
    # none of the known (limit 100): 2 of 4 unknown; 1 % (limit 99): 3; 2 %: the same; 60 %: all
    assert roc_at(known, unknown, (0.0, 0.01, 0.02, 0.6)) == [0.5, 0.75, 0.75, 1.0]


@pytest.mark.coil
def test_record_on_a_small_split(coil_root: Path, tmp_path: Path) -> None:
    record = tmp_path / "split.json"
    argv = ["--root", str(coil_root), "--known", "1-2", "--unknown", "3-4", "--components", "4"]
    rows = main([*argv, "--centers", "0", "90", "--test-poses", "-20", "30", "10", "--record", str(record)])
    assert [r[:2] for r in rows] == [
        ["0", "default"],
        ["0", "every pose"],
        ["90", "default"],
        ["90", "every pose"],
        ["median", "default"],
        ["median", "every pose"],
    ]
    assert rows[0][2] == 2 * 30 and rows[1][2] == 2 * 41  # -45..55 less the gallery's poses, or all of them
    assert all(isinstance(v, float) and 0 <= v <= 100 for r in rows for v in r[5:])
    saved = json.loads(record.read_text())
    assert saved["tables"][0]["rows"][0][:3] == ["0", "default", 60]
    assert saved["command"].startswith("python examples/diagnostics/rejection_split.py --root ")


def test_bad_arguments_exit_2(coil_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--root", str(tmp_path / "absent"), "--record", ""])
    assert info.value.code == 2 and "--root DIR" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:  # a pose COIL-20 does not hold
        main(["--root", str(coil_root), "--test-poses", "-42", "42", "5", "--record", ""])
    assert info.value.code == 2 and "42" in capsys.readouterr().err
