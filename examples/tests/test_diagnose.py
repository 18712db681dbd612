"""The pose and synthesis diagnoses (``examples/diagnostics/diagnose.py``): the pose summary,
the symmetric-object rule, the size-normalization rule and the command line."""

from __future__ import annotations

import json
from pathlib import Path

import diagnose
import pytest
import torch
from diagnose import PoseRecord, pose_summary, size_normalized, symmetric_objects

from torch_eigview import CoilFolder
from torch_eigview.warp import foreground_mask


def test_pose_summary_splits_objects_and_sector_positions() -> None:
    rows = [
        PoseRecord(1, 10.0, -4.0),
        PoseRecord(1, 55.0, -2.0),
        PoseRecord(1, 35.0, 2.0),
        PoseRecord(2, 10.0, 30.0),
    ]
    table = {row[0]: row[1:] for row in pose_summary(rows, 45.0, [2])}
    assert table["all"] == [4, 9.5, 3.0, 0.0]
    assert table["w/o 2"] == [3, pytest.approx(8 / 3), 2.0, -2.0]
    assert table["object 2"] == [1, 30.0, 30.0, 30.0]
    # 10 and 55 are both 10 degrees past their sector's first seed.
    assert table["sector +10"] == [3, 12.0, 4.0, -2.0]
    assert table["sector +35"] == [1, 2.0, 2.0, 2.0]


def test_pose_summary_without_records() -> None:
    name, n, *figures = pose_summary([], 45.0, [])[0]
    assert (name, n) == ("all", 0) and all(f != f for f in figures)  # NaN


def test_symmetric_objects_are_the_round_ones(folder: CoilFolder) -> None:
    # COIL-20's tub (15) and bowl (17) barely change as they turn; the duck (1) and the car (3) do.
    found = symmetric_objects(folder, [1, 3, 15, 17], 0.1)
    assert found == [15, 17]


def test_size_normalization_rule_is_the_synthesis_one(folder: CoilFolder) -> None:
    """COIL-20's views fill the frame: "auto" normalizes them; a view with a margin is not."""
    seeds = folder.images(1, [0.0, 10.0])
    assert size_normalized("auto", foreground_mask(seeds))
    framed = torch.nn.functional.pad(seeds, (20, 20, 20, 20))
    assert not size_normalized("auto", foreground_mask(framed))
    assert size_normalized(True, foreground_mask(framed)) and not size_normalized(
        False, foreground_mask(seeds)
    )


def test_pose_table_on_coil(coil_root: Path, tmp_path: Path) -> None:
    """One object, M = 4: the record holds the summary rows, the command that wrote it."""
    argv = ["pose", "--root", str(coil_root), "--objects", "2", "--pose-seeds", "4", "--components", "3"]
    out = diagnose.main([*argv, "--records", str(tmp_path)])
    rows = {row[0]: row for row in out["pose"]["rows"]}
    assert {"all", "object 2", "w/o -"} <= set(rows) and 0 < rows["all"][1] <= 68
    record = json.loads((tmp_path / "diagnose_pose.json").read_text())
    assert record["page"] == "results" and record["tables"][0]["rows"] == out["pose"]["rows"]
    assert record["command"].startswith("python examples/diagnostics/diagnose.py pose --root ")


def test_cli_errors_are_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exc:
        diagnose.main(["pose", "--root", str(tmp_path / "absent"), "--records", ""])
    assert exc.value.code == 2 and "absent" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        diagnose.main(["centers"])
    assert exc.value.code == 2 and "invalid choice: 'centers'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        diagnose.main(["pose", "--records", str(tmp_path / "no" / "such")])
    assert exc.value.code == 2 and "does not exist" in capsys.readouterr().err
