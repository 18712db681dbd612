"""The pose break-down of the diagnosis tool: its summary and the symmetric-object rule."""

from __future__ import annotations

import pytest

from torch_eigview.apps.diagnose import PoseRecord, pose_summary, symmetric_objects
from torch_eigview.datasets.coil import CoilFolder


def test_pose_summary_splits_objects_and_sector_positions() -> None:
    rows = [
        PoseRecord(1, 10.0, -4.0),
        PoseRecord(1, 55.0, -2.0),
        PoseRecord(1, 35.0, 2.0),
        PoseRecord(2, 10.0, 30.0),
    ]
    table = {line[:16].strip(): line[16:].split() for line in pose_summary(rows, 45.0, [2]).splitlines()[2:]}
    assert table["all"] == ["4", "9.50", "3.00", "+0.00"]
    assert table["w/o 2"] == ["3", "2.67", "2.00", "-2.00"]
    assert table["object 2"] == ["1", "30.00", "30.00", "+30.00"]
    # 10 and 55 are both 10 degrees past their sector's first seed.
    assert table["sector +10"] == ["3", "12.00", "4.00", "-2.00"]
    assert table["sector +35"] == ["1", "2.00", "2.00", "+2.00"]


def test_pose_summary_without_records() -> None:
    assert pose_summary([], 45.0, []).splitlines()[2].split() == ["all", "0", "nan", "nan", "nan"]


@pytest.mark.slow
def test_symmetric_objects_are_the_round_ones(folder: CoilFolder) -> None:
    # COIL-20's tub (15) and bowl (17) barely change as they turn; the duck (1) and the car (3) do.
    found = symmetric_objects(folder, [1, 3, 15, 17], 0.1)
    assert found == [15, 17]
