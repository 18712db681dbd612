"""The correspondence diagnosis (``examples/diagnostics/diagnose_flow.py``): the chained
reference motion against exact correspondences, the table on COIL-20 and its bad angles."""

from __future__ import annotations

import json
from pathlib import Path

import diagnose_flow
import pytest
import torch
import torch.nn.functional as F
from diagnose_flow import chained_disparity, correspondence_rows

from torch_eigview import estimate_correspondence
from torch_eigview.datasets import OrthographicCamera, exact_correspondence, make_object, render_views


def test_chained_disparity_follows_the_exact_motion() -> None:
    """Rendered views 5° apart, chained from 0° to 45°, against the exact disparity at 45°:
    within a pixel, where TV-L1 between the two ends alone is off by two."""
    obj, cam = make_object("head"), OrthographicCamera(96)
    views = render_views(obj, [5.0 * i for i in range(10)], cam)
    exact = exact_correspondence(obj, 45.0, cam)
    inner = -F.max_pool2d(-exact.valid_12.float()[None], 5, 1, 2)[0, 0] > 0.5
    chained = chained_disparity(views)
    direct = estimate_correspondence(views[:1], views[-1:], method="tvl1").disparity_12[0]
    err_chained = (chained - exact.disparity_12[0])[inner].abs().median()
    err_direct = (direct - exact.disparity_12[0])[inner].abs().median()
    assert float(err_chained) < 1.0 and float(err_direct) > 1.5, (err_chained, err_direct)
    # One view: no motion.
    assert torch.equal(chained_disparity(views[:1]), torch.zeros(96, 96))


def test_table_on_coil(coil_root: Path, tmp_path: Path) -> None:
    """The guided flow finds more of a 45° motion than TV-L1 alone on two COIL-20 objects."""
    argv = ["--root", str(coil_root), "--objects", "1,3", "--centers", "0", "--alphas", "45"]
    rows = diagnose_flow.main([*argv, "--flows", "tvl1", "guided", "--record", str(tmp_path / "r.json")])
    by_flow = {row[1]: row[2:] for row in rows}
    assert set(by_flow) == {"tvl1", "guided"}
    assert by_flow["guided"][0] > by_flow["tvl1"][0] + 0.2, rows
    assert by_flow["guided"][1] < by_flow["tvl1"][1], rows  # the median error in pixels
    assert all(0.0 <= row[2] <= 1.0 for row in by_flow.values())
    record = json.loads((tmp_path / "r.json").read_text())
    assert record["tables"][0]["rows"] == rows and record["title"].startswith("Diagnosis")


@pytest.mark.parametrize("alpha", [7.0, 0.0, -5.0])
def test_table_rejects_angles_off_the_pose_grid(alpha: float) -> None:
    with pytest.raises(
        ValueError, match=rf"alpha={alpha:g} must be a positive multiple of the poses' step 5"
    ):
        correspondence_rows(None, [1], [0.0], [alpha])  # type: ignore[arg-type]


def test_table_needs_objects_centers_and_angles() -> None:
    with pytest.raises(ValueError, match="objects, centers and alphas must each name at least one"):
        correspondence_rows(None, [], [0.0], [10.0])  # type: ignore[arg-type]


def test_cli_bad_angle_is_one_line(coil_root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        diagnose_flow.main(["--root", str(coil_root), "--objects", "1", "--alphas", "7", "--record", ""])
    assert exc.value.code == 2
    assert "alpha=7 must be a positive multiple of the poses' step 5" in capsys.readouterr().err
