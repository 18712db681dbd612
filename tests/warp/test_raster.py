"""2D map inversion by triangle rasterization: analytic maps, the row inversion, the z-buffer, what is left out."""

from __future__ import annotations

import math

import pytest
import torch

from torch_eigview.geometry.row_maps import invert_row_map
from torch_eigview.warp.raster import invert_map_2d

from tests.helpers import rand


def _grid(h: int, w: int, dtype: torch.dtype = torch.float64) -> tuple[torch.Tensor, torch.Tensor]:
    """(H, W) column and row of every pixel."""
    cols = torch.arange(w, dtype=dtype).expand(h, w)
    rows = torch.arange(h, dtype=dtype)[:, None].expand(h, w)
    return cols, rows


def _all_valid(b: int, h: int, w: int) -> torch.Tensor:
    return torch.ones(b, h, w, dtype=torch.bool)


# --- affine maps: barycentric interpolation is exact ------------------------------------

H, W = 32, 36
# (angle in degrees, scale, shift) per novel view: rotation about the image centre.
AFFINE = [(10.0, 1.1, (2.3, -1.7)), (-7.0, 0.9, (-0.4, 1.25))]


def _affine(i: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(2, 2) matrix A and (2,) offset o of the i-th map p -> A p + o, p = (x, y)."""
    angle, scale, shift = AFFINE[i]
    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    a = scale * torch.tensor([[c, -s], [s, c]], dtype=torch.float64)
    centre = torch.tensor([(W - 1) / 2, (H - 1) / 2], dtype=torch.float64)
    return a, centre - a @ centre + torch.tensor(shift, dtype=torch.float64)


def _affine_maps() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Forward maps (1, T, H, W) and the exact inverse (1, T, H, W) at every target pixel."""
    cols, rows = _grid(H, W)
    p = torch.stack([cols, rows], dim=-1)  # (H, W, 2)
    fwd, inv = [], []
    for i in range(len(AFFINE)):
        a, o = _affine(i)
        fwd.append(p @ a.T + o)
        inv.append((p - o) @ torch.linalg.inv(a).T)
    f, v = torch.stack(fwd)[None], torch.stack(inv)[None]
    return f[..., 0], f[..., 1], v[..., 0], v[..., 1]


def test_affine_map_is_inverted_exactly(dtype: torch.dtype, device: torch.device) -> None:
    dst_x, dst_y, inv_x, inv_y = _affine_maps()
    src_x, src_y, hit = invert_map_2d(
        dst_x.to(device, dtype), dst_y.to(device, dtype), _all_valid(1, H, W).to(device)
    )
    assert src_x.shape == src_y.shape == hit.shape == (1, len(AFFINE), H, W)
    assert src_x.dtype == src_y.dtype == dtype and hit.dtype == torch.bool
    assert src_x.device.type == device.type
    src_x, src_y, hit = src_x.cpu().double(), src_y.cpu().double(), hit.cpu()
    # float32 keeps 7 digits of coordinates up to ~40 px.
    atol = 1e-9 if dtype == torch.float64 else 2e-5
    torch.testing.assert_close(src_x[hit], inv_x[hit], atol=atol, rtol=0)
    torch.testing.assert_close(src_y[hit], inv_y[hit], atol=atol, rtol=0)
    assert bool(src_x[~hit].isnan().all()) and bool(src_y[~hit].isnan().all())
    # Every pixel whose inverse is inside the grid (1 px from its border) is hit; no
    # pixel whose inverse is outside it (beyond rounding) is.
    inner = (inv_x > 1) & (inv_x < W - 2) & (inv_y > 1) & (inv_y < H - 2)
    outer = (inv_x > -atol) & (inv_x < W - 1 + atol) & (inv_y > -atol) & (inv_y < H - 1 + atol)
    assert bool(hit[inner].all()) and not bool(hit[~outer].any())
    assert int(inner.sum()) > 0.5 * inner.numel()


# --- a homography: exact at the vertices, linear in between ------------------------------

HOMOGRAPHY = torch.tensor(
    [[1.04, 0.03, 1.3], [-0.02, 0.97, -0.6], [1.5e-3, -1.2e-3, 1.0]], dtype=torch.float64
)


def _apply(m: torch.Tensor, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    q = torch.stack([x, y, torch.ones_like(x)], dim=-1) @ m.T
    return q[..., 0] / q[..., 2], q[..., 1] / q[..., 2]


def test_homography_is_linear_between_vertices_and_exact_at_them() -> None:
    h = w = 64
    cols, rows = _grid(h, w)
    # Batch item k is the homography followed by the sub-pixel shift that lands vertex
    # VERTICES[k] on an integer target pixel (still a homography).
    vertices = [(5, 7), (31, 40), (58, 20)]
    fx, fy = _apply(HOMOGRAPHY, cols, rows)
    dst_x, dst_y, inverses, targets = [], [], [], []
    for col, row in vertices:
        sx, sy = float(fx[row, col].round() - fx[row, col]), float(fy[row, col].round() - fy[row, col])
        shifted = torch.tensor([[1.0, 0, sx], [0, 1.0, sy], [0, 0, 1.0]], dtype=torch.float64) @ HOMOGRAPHY
        dst_x.append(fx + sx)
        dst_y.append(fy + sy)
        inverses.append(torch.stack(_apply(torch.linalg.inv(shifted), cols, rows)))
        targets.append((int(fy[row, col].round()), int(fx[row, col].round())))
    src_x, src_y, hit = invert_map_2d(
        torch.stack(dst_x)[:, None], torch.stack(dst_y)[:, None], _all_valid(len(vertices), h, w)
    )
    inv = torch.stack(inverses)[:, :, None]  # (B, 2, 1, H, W)
    err = torch.maximum((src_x - inv[:, 0]).abs(), (src_y - inv[:, 1]).abs())[hit]
    # Linear interpolation of this mild homography over unit triangles errs by up to 4e-4
    # px (and the error is there: the map is not affine).
    assert 1e-5 < float(err.max()) < 2e-3
    inner = (inv[:, 0] > 1) & (inv[:, 0] < w - 2) & (inv[:, 1] > 1) & (inv[:, 1] < h - 2)
    assert bool(hit[inner].all())
    for k, ((col, row), (ty, tx)) in enumerate(zip(vertices, targets, strict=True)):
        assert bool(hit[k, 0, ty, tx])
        assert abs(float(src_x[k, 0, ty, tx]) - col) < 1e-9 and abs(float(src_y[k, 0, ty, tx]) - row) < 1e-9


# --- a row map: the 2D inversion is invert_row_map ----------------------------------------


def test_row_map_matches_invert_row_map() -> None:
    b, t, h, w = 2, 3, 10, 40
    cols, rows = _grid(h, w)
    phase = 6.0 * rand(b, t, 1, 1, seed=1)
    # Amplitude 7 with period 2 pi 5 folds the rows (slope 1 + 1.4 cos < 0): overlaps where
    # depth decides; phases drift slowly along the rows so vertical edges stay short.
    amp = torch.tensor([0.5, 3.0, 7.0], dtype=torch.float64).view(1, t, 1, 1)
    dst_x = cols + amp * torch.sin(cols / 5 + phase + rows / 9)
    dst_y = rows.expand(b, t, h, w).clone()
    depth = torch.cos(cols / 7 + 2 * phase) + 0.1 * rows
    valid = torch.ones(b, h, w, dtype=torch.bool)
    valid[:, :, 17] = False  # a column of untrusted pixels
    valid[0, 4, 30] = False  # an isolated one
    for dep, max_stretch in ((depth, math.inf), (None, math.inf), (depth, 3.0)):
        src_x, src_y, hit = invert_map_2d(dst_x, dst_y, valid, dep, max_stretch)
        ref_x, ref_hit = invert_row_map(dst_x, valid, dep, max_stretch)
        both = hit & ref_hit
        assert int(both.sum()) > 0.8 * int(ref_hit.sum())
        torch.testing.assert_close(src_x[both], ref_x[both], atol=1e-6, rtol=0)
        torch.testing.assert_close(src_y[hit], rows.expand_as(hit)[hit], atol=1e-12, rtol=0)
        # Target row j lies on the row-j edges of the triangles of cells j - 1 and j, which
        # interpolate (and orient) as invert_row_map's segments do. The masks can differ
        # only at rounding level at a segment's end (the 2D edges take a 1e3-epsilon slack),
        # or where both triangles on a segment are dropped for their third vertex: untrusted,
        # or a vertical or diagonal edge longer than max_stretch. Here that last case alone
        # occurs, where the strongly folding view (amplitude 7: slopes up to 2.4 px per column
        # plus 0.8 per row) meets max_stretch = 3; isolated untrusted pixels never drop both.
        if math.isinf(max_stretch):
            assert int((hit != ref_hit).sum()) <= 2
        else:
            assert int((hit & ~ref_hit).sum()) == 0
            assert not bool((hit != ref_hit)[:, :2].any())


# --- the z-buffer -----------------------------------------------------------------------


def test_nearest_surface_wins() -> None:
    h, w = 6, 16
    cols, rows = _grid(h, w)
    left = cols < w // 2
    # The left half slides 8 columns right and 1.25 rows up, over the right half.
    dst_x = torch.where(left, cols + w // 2, cols)[None, None]
    dst_y = torch.where(left, rows - 1.25, rows)[None, None]
    valid = _all_valid(1, h, w)
    covered = ~left & (rows <= 3)  # image of the left half (rows 4, 5 would sample below it)
    near_left = torch.where(left, 1.0, 0.0).expand(1, 1, h, w).double()
    # Without depth the larger src_y * W + src_x wins: the left half, 1.25 rows further down;
    # equal depths go to the later triangle in (b, t, j, l) order: the left half again.
    cases = ((near_left, True), (1 - near_left, False), (None, True), (0 * near_left, True))
    for depth, left_wins in cases:
        src_x, src_y, hit = invert_map_2d(dst_x, dst_y, valid, depth)
        # The cells across the seam are folded (dst_x drops from 15 to 8): nothing lands left.
        assert torch.equal(hit[0, 0], ~left)
        from_left = covered if left_wins else torch.zeros_like(covered)
        exp_x = torch.where(from_left, cols - w // 2, cols)
        exp_y = torch.where(from_left, rows + 1.25, rows)
        torch.testing.assert_close(src_x[0, 0][~left], exp_x[~left], atol=1e-12, rtol=0)
        torch.testing.assert_close(src_y[0, 0][~left], exp_y[~left], atol=1e-12, rtol=0)


def test_interpenetrating_surfaces_meet_where_their_depths_do() -> None:
    """Depth is interpolated linearly: a tilted plane through a flat one wins on its side."""
    h, w = 8, 16
    cols, rows = _grid(h, w)
    left = cols < w // 2
    # The left half moves onto the right half by an affine map (pixels land in both kinds
    # of triangle); its depth is a plane in its source coordinates, the right half's is 0.
    a = torch.tensor([[1.0, 0.13], [0.11, 1.0]], dtype=torch.float64)
    o = torch.tensor([8.3, -0.4], dtype=torch.float64)
    moved = torch.stack([cols, rows], dim=-1) @ a.T + o
    dst_x = torch.where(left, moved[..., 0], cols)[None, None]
    dst_y = torch.where(left, moved[..., 1], rows)[None, None]
    depth = torch.where(left, (cols - 4.0) + 0.1 * (rows - 3), 0.0)[None, None]
    src_x, src_y, hit = invert_map_2d(dst_x, dst_y, _all_valid(1, h, w), depth)
    back = (torch.stack([cols, rows], dim=-1) - o) @ torch.linalg.inv(a).T
    lx, ly = back[..., 0], back[..., 1]  # the left half's source position at each target pixel
    under = (lx >= 0) & (lx <= w // 2 - 1) & (ly >= 0) & (ly <= h - 1)
    wins = under & ((lx - 4.0) + 0.1 * (ly - 3) > 0)
    assert 5 < int(wins.sum()) < int(under.sum()) - 5  # the contest is split
    assert torch.equal(hit[0, 0], ~left)
    torch.testing.assert_close(src_x[0, 0][~left], torch.where(wins, lx, cols)[~left], atol=1e-12, rtol=0)
    torch.testing.assert_close(src_y[0, 0][~left], torch.where(wins, ly, rows)[~left], atol=1e-12, rtol=0)


# --- what is left out -------------------------------------------------------------------


def test_invalid_vertices_are_excluded() -> None:
    h, w = 6, 7
    cols, rows = _grid(h, w)
    dst_x, dst_y = cols.expand(1, 1, h, w), rows.expand(1, 1, h, w)
    depth = torch.ones(1, 1, h, w, dtype=torch.float64)
    valid = _all_valid(1, h, w)
    untrusted = valid.clone()
    untrusted[0, 2, 3] = False
    nan_x, nan_depth = dst_x.clone(), depth.clone()
    nan_x[0, 0, 2, 3] = nan_depth[0, 0, 2, 3] = math.nan
    # Identity: every pixel is a vertex; only the untrusted one (a False in valid, a NaN
    # in the map or in depth) loses all its triangles.
    expected = torch.ones(h, w, dtype=torch.bool)
    expected[2, 3] = False
    for args in (
        (dst_x, dst_y, untrusted, None),
        (nan_x, dst_y, valid, depth),
        (dst_x, dst_y, valid, nan_depth),
    ):
        src_x, src_y, hit = invert_map_2d(*args)
        assert torch.equal(hit[0, 0], expected)
        torch.testing.assert_close(src_x[0, 0][expected], cols[expected], atol=1e-12, rtol=0)
        torch.testing.assert_close(src_y[0, 0][expected], rows[expected], atol=1e-12, rtol=0)


def test_folded_triangles_are_excluded() -> None:
    h, w = 6, 7
    cols, rows = _grid(h, w)
    mirrored_x, mirrored_y = (w - 1 - cols)[None, None], (h - 1 - rows)[None, None]
    valid = _all_valid(1, h, w)
    # A mirror image reverses the winding: surface seen from behind, nothing is hit.
    for dst_x, dst_y in ((mirrored_x, rows[None, None]), (cols[None, None], mirrored_y)):
        src_x, _, hit = invert_map_2d(dst_x, dst_y, valid)
        assert not bool(hit.any()) and bool(src_x.isnan().all())
    # Mirroring both is a half turn, which keeps the winding.
    src_x, src_y, hit = invert_map_2d(mirrored_x, mirrored_y, valid)
    assert bool(hit.all())
    torch.testing.assert_close(src_x[0, 0], w - 1 - cols, atol=1e-12, rtol=0)
    torch.testing.assert_close(src_y[0, 0], h - 1 - rows, atol=1e-12, rtol=0)


def test_stretched_edges_are_excluded() -> None:
    h, w = 5, 9
    cols, rows = _grid(h, w)
    dst_x = torch.where(cols >= 4, cols + 3, cols)[None, None]  # a 4 px jump after column 3
    valid = _all_valid(1, h, w)
    gap = (cols > 3) & (cols < 7)
    _, _, hit = invert_map_2d(dst_x, rows[None, None], valid, max_stretch=3.0)
    assert torch.equal(hit[0, 0], ~gap)
    src_x, _, hit = invert_map_2d(dst_x, rows[None, None], valid)  # no limit: stretched over
    assert bool(hit.all())
    torch.testing.assert_close(src_x[0, 0][gap], 3 + (cols[gap] - 3) / 4, atol=1e-12, rtol=0)


# Linear maps p -> M p with one long kind of edge: horizontal, vertical or diagonal (3.5 px;
# the other two 2.02 px). Every triangle has one edge of each kind.
@pytest.mark.parametrize(
    "m",
    [((3.5, -1.75), (0.0, 1.0)), ((1.0, 0.0), (-1.75, 3.5)), ((1.75, 1.75), (-1.0, 1.0))],
    ids=["horizontal", "vertical", "diagonal"],
)
def test_each_edge_is_checked_against_max_stretch(m: tuple[tuple[float, float], ...]) -> None:
    h, w = 10, 12
    cols, rows = _grid(h, w)
    (a, b), (c, d) = m
    cx, cy = (w - 1) / 2, (h - 1) / 2  # kept in place
    dst_x = (cx + a * (cols - cx) + b * (rows - cy))[None, None]
    dst_y = (cy + c * (cols - cx) + d * (rows - cy))[None, None]
    assert not bool(invert_map_2d(dst_x, dst_y, _all_valid(1, h, w), max_stretch=3.4)[2].any())
    _, _, hit = invert_map_2d(dst_x, dst_y, _all_valid(1, h, w), max_stretch=3.6)
    assert int(hit.sum()) > 20


@pytest.mark.parametrize(("inside", "outside"), [(1e-14, 1e-9), (1e-6, 1e-2)], ids=["float64", "float32"])
def test_edges_are_inclusive_with_a_rounding_slack(inside: float, outside: float) -> None:
    """A pixel just off the surface's border (by rounding) is hit; one clearly off it is not."""
    dtype = torch.float64 if inside < 1e-10 else torch.float32
    h, w = 4, 5
    cols, rows = _grid(h, w, dtype)
    for shift in (inside, -inside, outside, -outside):
        src_x, _, hit = invert_map_2d((cols + shift)[None, None], rows[None, None], _all_valid(1, h, w))
        border = 0 if shift > 0 else w - 1  # the column the shift moves the surface off
        assert bool(hit[..., 1:-1].all()) and bool(hit[..., border].all()) == (abs(shift) == inside)
        torch.testing.assert_close(src_x[hit], (cols - shift).expand_as(hit)[hit], atol=1e-5, rtol=0)


@pytest.mark.parametrize("size", [(6, 7), (1, 7), (6, 1)])
def test_nothing_valid_gives_an_empty_result(size: tuple[int, int], dtype: torch.dtype) -> None:
    h, w = size
    cols, rows = _grid(h, w, dtype)
    valid = torch.zeros(2, h, w, dtype=torch.bool) if h > 1 and w > 1 else _all_valid(2, h, w)
    src_x, src_y, hit = invert_map_2d(cols.expand(2, 3, h, w), rows.expand(2, 3, h, w), valid)
    assert src_x.shape == src_y.shape == hit.shape == (2, 3, h, w) and src_x.dtype == dtype
    assert not bool(hit.any()) and bool(src_x.isnan().all()) and bool(src_y.isnan().all())


def test_bad_arguments_are_rejected() -> None:
    x = torch.zeros(1, 2, 4, 5)
    ok = _all_valid(1, 4, 5)
    with pytest.raises(ValueError, match=r"dst_x must have shape \(B, T, H, W\)"):
        invert_map_2d(x[0], x[0], ok)
    with pytest.raises(
        ValueError, match=r"dst_y must have the shape of dst_x \(1, 2, 4, 5\), got \(1, 2, 5, 4\)"
    ):
        invert_map_2d(x, x.transpose(-1, -2), ok)
    with pytest.raises(
        ValueError, match=r"valid must have shape .*\(1, 4, 5\).*\(1, 2, 4, 5\), got \(1, 4, 4\)"
    ):
        invert_map_2d(x, x, ok[:, :, :4])
    with pytest.raises(
        ValueError, match=r"depth must have the shape of dst_x \(1, 2, 4, 5\), got \(1, 4, 5\)"
    ):
        invert_map_2d(x, x, ok, x[:, 0])
    with pytest.raises(TypeError, match="dst_x must have a floating dtype"):
        invert_map_2d(x.long(), x, ok)
    with pytest.raises(TypeError, match="dst_y must have the dtype of dst_x"):
        invert_map_2d(x, x.double(), ok)
    with pytest.raises(TypeError, match=r"valid must have dtype torch\.bool"):
        invert_map_2d(x, x, ok.float())
    with pytest.raises(TypeError, match="depth must have a floating dtype"):
        invert_map_2d(x, x, ok, x.int())
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError, match="max_stretch must be positive"):
            invert_map_2d(x, x, ok, max_stretch=bad)
    with pytest.raises(TypeError, match="max_stretch must be a number"):
        invert_map_2d(x, x, ok, max_stretch="3")  # type: ignore[arg-type]
