"""Inverse of a 2D forward map by triangle rasterization with a z-buffer (perspective, Sec. 4).

Convention:
    Maps are (B, T, H, W) in pixels, as in :mod:`torch_eigview.warp.novel_view`: x is the column, y
    the row, pixel centres at integer coordinates. The forward map sends source pixel
    (row j, column l) to ``(dst_x, dst_y)[..., j, l]`` in the target image; its inverse gives
    each target pixel the source position ``(src_x, src_y)`` it samples (NaN where nothing
    lands). Each source cell (j, l)-(j + 1, l + 1) is cut along its diagonal
    (j, l)-(j + 1, l + 1) into two triangles with vertices, as (x, y),

    - "upper": (l, j), (l + 1, j), (l + 1, j + 1);
    - "lower": (l, j), (l + 1, j + 1), (l, j + 1).

    Both wind positively, ``(b - a) x (c - a) > 0`` with ``u x v = u_x v_y - u_y v_x``; a
    triangle whose forward image winds the other way is folded (surface turned away from
    the novel camera), like a segment of :func:`~torch_eigview.geometry.row_maps.invert_row_map` whose
    order flips. Depth grows towards the novel camera: where triangles overlap, the one
    with the largest interpolated depth wins.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from torch_eigview.check import check_float_tensor, check_ndim, check_number

__all__ = ["invert_map_2d"]


def _edge_tolerance(dtype: torch.dtype) -> float:
    """Barycentric slack of the inside test: 2.2e-13 for float64, 1.2e-4 for float32."""
    return 1e3 * torch.finfo(dtype).eps


def _check_inputs(
    dst_x: object, dst_y: object, valid: object, depth: object, max_stretch: object
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None, float]:
    """Validates the arguments of :func:`invert_map_2d`; all tensors go to ``dst_x``'s device."""
    x = check_float_tensor(dst_x, "dst_x")
    check_ndim(x, "dst_x", (4,), "(B, T, H, W)")
    b, t, h, w = x.shape
    y = check_float_tensor(dst_y, "dst_y")
    if y.shape != x.shape:
        raise ValueError(f"dst_y must have the shape of dst_x {tuple(x.shape)}, got {tuple(y.shape)}")
    if y.dtype != x.dtype:
        raise TypeError(f"dst_y must have the dtype of dst_x ({x.dtype}), got {y.dtype}")
    if not isinstance(valid, torch.Tensor):
        raise TypeError(f"valid must be a torch.Tensor, got {type(valid).__name__}")
    if valid.dtype != torch.bool:
        raise TypeError(f"valid must have dtype torch.bool, got {valid.dtype}")
    if valid.shape not in ((b, h, w), (b, t, h, w)):
        raise ValueError(
            f"valid must have shape (B, H, W) = {(b, h, w)} or (B, T, H, W) = {(b, t, h, w)}, "
            f"got {tuple(valid.shape)}"
        )
    d = None
    if depth is not None:
        d = check_float_tensor(depth, "depth")
        if d.shape != x.shape:
            raise ValueError(f"depth must have the shape of dst_x {tuple(x.shape)}, got {tuple(d.shape)}")
        d = d.to(device=x.device)
    stretch = check_number(max_stretch, "max_stretch")
    if not stretch > 0:
        raise ValueError(f"max_stretch must be positive, got {max_stretch}")
    return x, y.to(device=x.device), valid.to(device=x.device), d, stretch


class _Cells(NamedTuple):
    """The N = B T (H - 1) (W - 1) cells of the source grid, flat in (b, t, j, l) order.

    Each cell's box is the target pixels around its used triangles; its first pixel
    (x0, y0) is candidate 0, pixel (x0 + m % nx, y0 + m // nx) candidate m < ``size``.
    Geometry, in the target, relative to the cell's vertex a = (j, l): ``d*0`` from a to
    (x0, y0); ``g*`` the diagonal a -> (j + 1, l + 1); ``h*`` (B, T, H, W - 1) the
    horizontal and ``v*`` (B, T, H - 1, W) the vertical edges of the grid (the top edge
    a -> (j, l + 1) of the cell and its left edge a -> (j + 1, l)); ``inv_*`` 1 / twice the
    signed area of the upper and the lower triangle, NaN where the triangle is not used.
    """

    size: torch.Tensor  # (N,) long: pixels in the box, 0 when no triangle is used
    nx: torch.Tensor  # (N,) long: box width
    base: torch.Tensor  # (N,) long: flat target index of (x0, y0)
    dx0: torch.Tensor  # (B, T, H - 1, W - 1), like gx, gy, inv_u, inv_l
    dy0: torch.Tensor
    gx: torch.Tensor
    gy: torch.Tensor
    hx: torch.Tensor
    hy: torch.Tensor
    vx: torch.Tensor
    vy: torch.Tensor
    inv_u: torch.Tensor
    inv_l: torch.Tensor

    def grid(self) -> tuple[torch.Tensor, torch.Tensor, tuple[torch.Tensor, ...]]:
        """``(dx0, dy0, edges)`` of every cell, (B, T, H - 1, W - 1) each."""
        top = (self.hx[..., :-1, :], self.hy[..., :-1, :])
        left = (self.vx[..., :-1], self.vy[..., :-1])
        return self.dx0, self.dy0, (self.gx, self.gy, *top, *left, self.inv_u, self.inv_l)

    def at(self, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, tuple[torch.Tensor, ...]]:
        """``(dx0, dy0, edges)`` of the cells ``c`` (flat indices), (len(c),) each."""
        h, w1 = self.vx.shape[-2] + 1, self.hx.shape[-1]
        rows = torch.div(c, w1, rounding_mode="floor")  # b t (H - 1) + j
        top = c + torch.div(rows, h - 1, rounding_mode="floor") * w1  # (b t H + j) (W - 1) + l
        left = c + rows  # (b t (H - 1) + j) W + l
        flat = [v.reshape(-1) for v in self]
        dx0, dy0, gx, gy, hx, hy, vx, vy, inv_u, inv_l = flat[3:]
        edges = (gx[c], gy[c], hx[top], hy[top], vx[left], vy[left], inv_u[c], inv_l[c])
        return dx0[c], dy0[c], edges


def _cells(x: torch.Tensor, y: torch.Tensor, valid: torch.Tensor, stretch: float, tol: float) -> _Cells:
    """Used triangles and candidate boxes of every cell (see :class:`_Cells`)."""
    b, t, h, w = x.shape
    x00, y00 = x[..., :-1, :-1], y[..., :-1, :-1]
    hx, hy = x[..., 1:] - x[..., :-1], y[..., 1:] - y[..., :-1]  # horizontal edges
    vx, vy = x[..., 1:, :] - x[..., :-1, :], y[..., 1:, :] - y[..., :-1, :]  # vertical edges
    gx, gy = x[..., 1:, 1:] - x00, y[..., 1:, 1:] - y00  # diagonals
    htx, hty = hx[..., :-1, :], hy[..., :-1, :]  # top edge: a -> b of the upper triangle
    vlx, vly = vx[..., :-1], vy[..., :-1]  # left edge: a -> c of the lower triangle
    area_u = htx * gy - hty * gx  # twice the signed areas; NaN or inf: not a surface
    area_l = gx * vly - gy * vlx
    ok_u = (area_u > 0) & (area_u < math.inf)
    ok_l = (area_l > 0) & (area_l < math.inf)
    # Edges with both ends valid; a triangle's horizontal and vertical edges hold its three
    # vertices between them, so the diagonal needs only the length check.
    h_ok = valid[..., 1:] & valid[..., :-1]
    v_ok = valid[..., 1:, :] & valid[..., :-1, :]
    if math.isfinite(stretch):
        s2 = stretch * stretch
        h_ok = h_ok & (hx * hx + hy * hy <= s2)
        v_ok = v_ok & (vx * vx + vy * vy <= s2)
        g_ok = gx * gx + gy * gy <= s2
        ok_u &= g_ok
        ok_l &= g_ok
    ok_u &= h_ok[..., :-1, :] & v_ok[..., 1:]
    ok_l &= h_ok[..., 1:, :] & v_ok[..., :-1]

    # The box spans the vertices of the used triangles (a, shared by both, stands in for
    # an unused one), widened by what the barycentric slack admits (2 tol per extent) and
    # clipped to the image; cells with no used triangle get size 0.
    corner, width = [], []
    for v, size in ((x, w), (y, h)):
        v00, v11 = v[..., :-1, :-1], v[..., 1:, 1:]
        v01 = torch.where(ok_u, v[..., :-1, 1:], v00)
        v10 = torch.where(ok_l, v[..., 1:, :-1], v00)
        lo = torch.minimum(torch.minimum(v00, v11), torch.minimum(v01, v10))
        hi = torch.maximum(torch.maximum(v00, v11), torch.maximum(v01, v10))
        pad = (hi - lo + 1) * (2 * tol)
        v0 = torch.ceil(lo - pad).clamp_(0, size)
        corner.append(v0)
        width.append((torch.floor(hi + pad).clamp_(-1, size - 1) - v0 + 1).clamp_(min=0))
    x0, y0 = corner
    nx, ny = width
    count = torch.where(ok_u | ok_l, nx * ny, 0).long().reshape(-1)
    frame = torch.arange(b * t, device=x.device).view(b, t, 1, 1) * (h * w)
    base = (frame + y0.long() * w + x0.long()).reshape(-1)
    inv_u = torch.where(ok_u, 1 / area_u, math.nan)
    inv_l = torch.where(ok_l, 1 / area_l, math.nan)
    dx0, dy0 = x0 - x00, y0 - y00
    return _Cells(count, nx.long().reshape(-1), base, dx0, dy0, gx, gy, hx, hy, vx, vy, inv_u, inv_l)


def _barycentric(
    dx: torch.Tensor, dy: torch.Tensor, edges: tuple[torch.Tensor, ...], tol: float
) -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """``(wb, wc, inside)`` in the upper and the lower triangle of pixels at ``(dx, dy)`` from a."""
    gx, gy, htx, hty, vlx, vly, inv_u, inv_l = edges
    cross = dx * gy - dy * gx  # (p - a) x (diagonal), shared by both triangles
    out = []
    for wb, wc in (
        (cross * inv_u, (htx * dy - hty * dx) * inv_u),
        ((dx * vly - dy * vlx) * inv_l, -cross * inv_l),
    ):
        out.append((wb, wc, (wb >= -tol) & (wc >= -tol) & (wb + wc <= 1 + tol)))
    return out


def invert_map_2d(
    dst_x: torch.Tensor,
    dst_y: torch.Tensor,
    valid: torch.Tensor,
    depth: torch.Tensor | None = None,
    max_stretch: float = math.inf,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Inverts a 2D forward map: the source position sampled by each target pixel.

    The source grid is cut into triangles (see the module docstring). A triangle is used
    when its three vertices are valid, have a finite forward map (and depth), its forward
    image winds positively (not folded) and each of its forward-mapped edges is at most
    ``max_stretch`` target pixels long (longer is a depth jump, not a surface). Every
    integer target pixel inside a used triangle takes the barycentric interpolation of the
    triangle's source vertices (exact for an affine forward map) and of their depths.

    Edges are inclusive with a slack: a pixel is inside when its three barycentric
    coordinates are ``>= -tol`` (``tol`` = 1e3 machine epsilons of the working dtype:
    2.2e-13 for float64, 1.2e-4 for float32), so a pixel on an edge shared by two triangles
    is taken by both (the z-buffer keeps one, their values agree) and rounding opens no
    cracks. A pixel on the border of the mapped grid may thus sample a source position
    up to about ``tol`` pixels outside it.

    Where triangles overlap the largest depth wins (``scatter_reduce_`` "amax", as in
    :func:`~torch_eigview.geometry.row_maps.invert_row_map`). Without ``depth`` the key is the source
    position in raster order, ``src_y * W + src_x`` (for a row map: the largest source
    column, as ``invert_row_map``). Equal keys go to the later triangle in the order
    (b, t, j, l, upper before lower).

    The work is one candidate per target pixel in the bounding box of each cell's used
    triangles, so ``max_stretch`` also bounds the cost of wild maps.

    Args:
        dst_x: (B, T, H, W) target column of each source pixel.
        dst_y: (B, T, H, W) target row of each source pixel, dtype of ``dst_x``.
        valid: (B, H, W) or (B, T, H, W) bool, source pixels with a trusted forward map.
        depth: (B, T, H, W) depth towards the novel camera (larger = nearer), or None.
        max_stretch: longest forward-mapped triangle edge (target pixels) still taken as
            one surface; positive, ``math.inf`` for no limit.

    Returns:
        ``(src_x, src_y, hit)``, (B, T, H, W) each: the source column and row of each
        target pixel in the dtype of ``dst_x`` (NaN where ``hit`` is False), and ``hit``
        (bool), True where a used triangle covers the pixel.

    Raises:
        TypeError: a map or ``depth`` is not a floating tensor, ``dst_y``'s dtype differs
            from ``dst_x``'s, ``valid`` is not a bool tensor, ``max_stretch`` not a number.
        ValueError: a shape does not match ``dst_x``'s, or ``max_stretch`` is not positive.

    Example:
        >>> x = torch.arange(4.0).expand(1, 1, 3, 4) + 0.5
        >>> y = torch.arange(3.0)[:, None].expand(1, 1, 3, 4)
        >>> src_x, src_y, hit = invert_map_2d(x, y, torch.ones(1, 3, 4, dtype=torch.bool))
        >>> src_x[0, 0, 0].tolist(), hit[0, 0, 0].tolist()
        ([nan, 0.5, 1.5, 2.5], [False, True, True, True])
    """
    x, y, valid, depth, stretch = _check_inputs(dst_x, dst_y, valid, depth, max_stretch)
    out_dtype, device = x.dtype, x.device
    # Half precision has too few digits for pixel coordinates: work in float32 at least.
    dtype = out_dtype if out_dtype in (torch.float32, torch.float64) else torch.float32
    b, t, h, w = x.shape
    n = b * t * h * w
    src_x = torch.full((n,), math.nan, dtype=dtype, device=device)
    src_y = torch.full((n,), math.nan, dtype=dtype, device=device)
    hit = torch.zeros(n, dtype=torch.bool, device=device)
    if h >= 2 and w >= 2 and n > 0:
        x, y = x.to(dtype).contiguous(), y.to(dtype).contiguous()
        valid = valid[:, None] if valid.ndim == 3 else valid
        if depth is not None:
            depth = depth.to(dtype)
            valid = valid & torch.isfinite(depth)
        tol = _edge_tolerance(dtype)
        hits = _candidate_hits(_cells(x, y, valid, stretch, tol), w, tol)
        _zbuffer(_hit_positions(hits, depth, h, w), src_x, src_y, hit)
    shape = (b, t, h, w)
    return src_x.view(shape).to(out_dtype), src_y.view(shape).to(out_dtype), hit.view(shape)


_Hit = tuple[int, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]


def _candidate_hits(cells: _Cells, w: int, tol: float) -> list[_Hit]:
    """The target pixels inside used triangles: ``(k, cell, pixel, wb, wc)`` per batch of
    hits, ``k`` 0 for the upper and 1 for the lower triangle, ``pixel`` the flat target
    index, ``wb``, ``wc`` the barycentric coordinates (all but ``k`` (P,))."""
    # Candidate m of a box is its pixel (x0 + m % nx, y0 + m // nx). Most boxes hold one
    # pixel, so candidates 0 are tested on the whole grid without gathers, the others
    # (boxes of 2 to a few pixels) gathered.
    hits = []
    has = cells.size > 0
    dx0, dy0, edges = cells.grid()
    for k, (wb, wc, inside) in enumerate(_barycentric(dx0, dy0, edges, tol)):
        c = (inside.reshape(-1) & has).nonzero().squeeze(1)
        hits.append((k, c, cells.base[c], wb.reshape(-1)[c], wc.reshape(-1)[c]))
    more = (cells.size > 1).nonzero().squeeze(1)
    extra = cells.size[more] - 1
    total = int(extra.sum())
    if total:
        device = more.device
        first = torch.cumsum(extra, 0) - extra
        i = torch.repeat_interleave(torch.arange(more.numel(), device=device), extra, output_size=total)
        c = more[i]
        m = torch.arange(1, total + 1, device=device) - first[i]
        nx = cells.nx[c]
        oy = torch.div(m, nx, rounding_mode="floor")
        ox = m - oy * nx
        dx0, dy0, edges = cells.at(c)
        for k, (wb, wc, inside) in enumerate(_barycentric(dx0 + ox, dy0 + oy, edges, tol)):
            j = inside.nonzero().squeeze(1)
            hits.append((k, c[j], cells.base[c[j]] + oy[j] * w + ox[j], wb[j], wc[j]))
    return hits


_Part = tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]


def _hit_positions(hits: list[_Hit], depth: torch.Tensor | None, h: int, w: int) -> list[_Part]:
    """``(pixel, key, triangle id, src_x, src_y)`` of each batch of hits: the source
    position ``(l, j) + wb (b - a) + wc (c - a)`` and the z-buffer key (the interpolated
    depth, or the raster position ``src_y * W + src_x`` without depth)."""
    parts = []
    for k, c, pix, wb, wc in hits:
        rows = torch.div(c, w - 1, rounding_mode="floor")  # b t (H - 1) + j
        col = c - rows * (w - 1)
        frame = torch.div(rows, h - 1, rounding_mode="floor")
        line = rows - frame * (h - 1)
        sx = col.to(wb.dtype) + (wb + wc if k == 0 else wb)
        sy = line.to(wb.dtype) + (wc if k == 0 else wb + wc)
        if depth is None:
            key = sy * w + sx
        else:
            d = depth.reshape(-1)
            a = (frame * h + line) * w + col  # flat index of vertex a = (j, l)
            da = d[a]
            db = d[a + 1] if k == 0 else d[a + w + 1]
            dc = d[a + w + 1] if k == 0 else d[a + w]
            key = da + wb * (db - da) + wc * (dc - da)
        parts.append((pix, key, 2 * c + k, sx, sy))
    return parts


def _zbuffer(parts: list[_Part], src_x: torch.Tensor, src_y: torch.Tensor, hit: torch.Tensor) -> None:
    """Writes the winning hit of each target pixel into the flat (N,) ``src_x``, ``src_y``
    and ``hit``: the largest key; equal keys go to the largest triangle id."""
    n = src_x.numel()
    best = torch.full((n,), -math.inf, dtype=src_x.dtype, device=src_x.device)
    for pix, key, _, _, _ in parts:
        best.scatter_reduce_(0, pix, key, reduce="amax")
    last = torch.full((n,), -1, dtype=torch.long, device=src_x.device)
    wins = []
    for pix, key, tid, _, _ in parts:
        win = (key >= best[pix]).nonzero().squeeze(1)
        last.scatter_reduce_(0, pix[win], tid[win], reduce="amax")
        wins.append(win)
    for (pix, _, tid, sx, sy), win in zip(parts, wins, strict=True):
        chosen = win[tid[win] == last[pix[win]]]  # one per hit pixel over all parts
        where = pix[chosen]
        src_x[where] = sx[chosen]
        src_y[where] = sy[chosen]
        hit[where] = True
