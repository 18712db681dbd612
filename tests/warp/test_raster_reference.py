"""2D map inversion against a loop over triangles and pixels, written as its docstring says."""

from __future__ import annotations

import itertools
import math

import pytest
import torch

from torch_eigview.warp.raster import invert_map_2d

from tests.helpers import rand


def _reference(
    dst_x: torch.Tensor,
    dst_y: torch.Tensor,
    valid: torch.Tensor,
    depth: torch.Tensor | None,
    max_stretch: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Triangle by triangle, pixel by pixel: the definition in invert_map_2d's docstring."""
    b, t, h, w = dst_x.shape
    tol = 1e3 * torch.finfo(torch.float64).eps
    valid = valid[:, None].expand(b, t, h, w) if valid.ndim == 3 else valid
    src_x = torch.full((b, t, h, w), math.nan, dtype=torch.float64)
    src_y = src_x.clone()
    best: dict[tuple[int, int, int, int], tuple[float, int]] = {}
    # (row, column) of the vertices a, b, c of the upper (k = 0) and lower (k = 1) triangle.
    shapes = [((0, 0), (0, 1), (1, 1)), ((0, 0), (1, 1), (1, 0))]
    cells = itertools.product(range(b), range(t), range(h - 1), range(w - 1), range(2))
    for tid, (bi, ti, j, col, k) in enumerate(cells):  # tid: 2 * flat cell index + k
        vs = [(bi, ti, j + dj, col + dl) for dj, dl in shapes[k]]
        if not all(bool(valid[v]) for v in vs):
            continue
        px, py = [float(dst_x[v]) for v in vs], [float(dst_y[v]) for v in vs]
        area = (px[1] - px[0]) * (py[2] - py[0]) - (py[1] - py[0]) * (px[2] - px[0])
        edges = [math.hypot(px[i] - px[i - 1], py[i] - py[i - 1]) for i in range(3)]
        if not (area > 0 and max(edges) <= max_stretch):
            continue
        for ty, tx in itertools.product(range(h), range(w)):
            dx, dy = tx - px[0], ty - py[0]
            wb = (dx * (py[2] - py[0]) - dy * (px[2] - px[0])) / area
            wc = ((px[1] - px[0]) * dy - (py[1] - py[0]) * dx) / area
            if min(wb, wc, 1 - wb - wc) < -tol:
                continue
            sy, sx = (
                sum(wgt * v[i] for wgt, v in zip((1 - wb - wc, wb, wc), vs, strict=True)) for i in (2, 3)
            )
            if depth is None:
                key = sy * w + sx
            else:
                d = [float(depth[v]) for v in vs]
                key = d[0] + wb * (d[1] - d[0]) + wc * (d[2] - d[0])
            here = (bi, ti, ty, tx)
            if here not in best or (key, tid) > best[here]:
                best[here] = (key, tid)
                src_x[here], src_y[here] = sx, sy
    return src_x, src_y, ~src_x.isnan()


@pytest.mark.parametrize("max_stretch", [math.inf, 3.0])
@pytest.mark.parametrize("with_depth", [True, False])
def test_matches_loop_reference(max_stretch: float, with_depth: bool) -> None:
    b, t, h, w = 2, 3, 6, 7
    cols = torch.arange(w, dtype=torch.float64).expand(h, w)
    rows = torch.arange(h, dtype=torch.float64)[:, None].expand(h, w)
    ph = 6.0 * rand(4, b, t, 1, 1, seed=2)
    # Smooth maps whose rows fold twice (slope 0.8 + 1.9 cos): the rising parts overlap,
    # the falling one is turned away; some long edges and untrusted pixels.
    dst_x = 3 + 0.8 * (cols - 3) + 1.2 * torch.sin(1.6 * (cols - 3) + 0.3 * ph[0] + rows / 3)
    dst_y = -0.3 + rows + 0.5 * torch.sin(cols / 2 + ph[2]) + 0.05 * cols * rows / (1 + ph[3])
    valid = rand(b, t, h, w, seed=3) > 0.12
    depth = torch.sin(cols / 1.5 + ph[3]) + torch.cos(rows / 2 + ph[0]) if with_depth else None
    src_x, src_y, hit = invert_map_2d(dst_x, dst_y, valid, depth, max_stretch=max_stretch)
    ref_x, ref_y, ref_hit = _reference(dst_x, dst_y, valid, depth, max_stretch)
    assert torch.equal(hit, ref_hit) and 0.3 * hit.numel() < int(hit.sum()) < hit.numel()
    torch.testing.assert_close(src_x, ref_x, atol=1e-9, rtol=0, equal_nan=True)
    torch.testing.assert_close(src_y, ref_y, atol=1e-9, rtol=0, equal_nan=True)
    if with_depth:  # the surfaces do overlap: the depth decides somewhere
        other_x = invert_map_2d(dst_x, dst_y, valid, -depth, max_stretch=max_stretch)[0]
        assert int(((other_x - src_x).abs() > 0.1).sum()) >= 3
