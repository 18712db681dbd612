"""The correspondence table of the diagnosis tool: the chained reference motion against
exact correspondences, the table on COIL-20 and its bad angles."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from torch_eigview.apps.diagnose_flow import chained_disparity, correspondence_table
from torch_eigview.datasets.cameras import OrthographicCamera
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.datasets.correspondence import exact_correspondence
from torch_eigview.datasets.renderer import render_views
from torch_eigview.datasets.shapes import make_object


def test_chained_disparity_follows_the_exact_motion() -> None:
    """Rendered views 5° apart, chained from 0° to 45°, against the exact disparity at 45°:
    within a pixel, where TV-L1 between the two ends alone is off by two."""
    from torch_eigview.geometry.tvl1 import tvl1_flow

    obj, cam = make_object("head"), OrthographicCamera(96)
    views = render_views(obj, [5.0 * i for i in range(10)], cam)
    exact = exact_correspondence(obj, 45.0, cam)
    inner = -F.max_pool2d(-exact.valid_12.float()[None], 5, 1, 2)[0, 0] > 0.5
    chained = chained_disparity(views)
    direct = tvl1_flow(views[0, 0], views[-1, 0])[1]
    err_chained = (chained - exact.disparity_12[0])[inner].abs().median()
    err_direct = (direct - exact.disparity_12[0])[inner].abs().median()
    assert float(err_chained) < 1.0 and float(err_direct) > 1.5, (err_chained, err_direct)
    # One view: no motion.
    assert torch.equal(chained_disparity(views[:1]), torch.zeros(96, 96))


@pytest.mark.slow
def test_table_on_coil(folder: CoilFolder) -> None:
    """The guided flow finds more of a 45° motion than TV-L1 alone on two COIL-20 objects."""
    table = correspondence_table(folder, [1, 3], [0.0], [45.0], flows=("tvl1", "guided"))
    rows = {line.split()[1]: [float(v) for v in line.split()[2:]] for line in table.splitlines()[2:]}
    assert set(rows) == {"tvl1", "guided"}
    assert rows["guided"][0] > rows["tvl1"][0] + 0.2, rows
    assert rows["guided"][1] < rows["tvl1"][1], rows  # the median error in pixels
    assert all(0.0 <= row[2] <= 1.0 for row in rows.values())


@pytest.mark.parametrize("alpha", [7.0, 0.0, -5.0])
def test_table_rejects_angles_off_the_pose_grid(alpha: float) -> None:
    with pytest.raises(
        ValueError, match=rf"alpha={alpha:g} must be a positive multiple of the poses' step 5"
    ):
        correspondence_table(None, [1], [0.0], [alpha])  # type: ignore[arg-type]


def test_table_needs_objects_centers_and_angles() -> None:
    with pytest.raises(ValueError, match="objects, centers and alphas must each name at least one"):
        correspondence_table(None, [], [0.0], [10.0])  # type: ignore[arg-type]
