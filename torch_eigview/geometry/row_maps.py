"""Inverting a forward map along rows: the source column each target pixel samples.

The orthographic camera rotating about the vertical axis moves pixels along their rows
(Eq. 2), so a seed view's forward map ``x3(x1)`` is inverted row by row:
:func:`invert_row_map` scans the map's segments (z-buffered where the surface folds) and
:func:`fill_row_holes` continues the inverse over target pixels no segment covers.
:class:`~torch_eigview.warp.novel_view.NovelViewWarp` builds its maps with both.
"""

from __future__ import annotations

import math

import torch

__all__ = ["fill_row_holes", "invert_row_map"]


def invert_row_map(
    dst_x_for_src: torch.Tensor,
    valid: torch.Tensor,
    depth: torch.Tensor | None,
    max_stretch: float = math.inf,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Inverts a forward map along rows: the source column sampled by each target pixel.

    Each pair of neighbouring valid source pixels (k, k + 1) whose targets keep their
    order and lie at most ``max_stretch`` pixels apart is a segment mapped linearly onto
    the target row; every integer target column it covers takes the linearly inverted
    source column. Segments whose order flips are surface turned away from the novel
    camera; where segments overlap the one nearest the camera (largest ``depth``) wins,
    like a z-buffer. A segment with a non-finite end (map or depth) is left out.

    Args:
        dst_x_for_src: (B, T, H, W) forward map x3(x1) in pixels.
        valid: (B, H, W) or (B, T, H, W) bool, source pixels with a trusted correspondence.
        depth: (B, T, H, W) depth towards the novel camera, or None (ties: largest source x).
        max_stretch: longest segment (target pixels) still taken as one surface.

    Returns:
        ``(src_x_for_dst, hit)``, (B, T, H, W) each; ``src_x_for_dst`` is NaN where
        ``hit`` is False.
    """
    b, t, h, w = dst_x_for_src.shape
    dtype, device = dst_x_for_src.dtype, dst_x_for_src.device
    n = b * t * h * w
    f0, f1 = dst_x_for_src[..., :-1], dst_x_for_src[..., 1:]
    length = f1 - f0
    valid = valid[:, None] if valid.ndim == 3 else valid
    seg_ok = (valid[..., :-1] & valid[..., 1:]) & (length > 0) & (length <= max_stretch)
    if w < 2 or not bool(seg_ok.any()):
        return torch.full((b, t, h, w), math.nan, dtype=dtype, device=device), seg_ok.new_zeros(b, t, h, w)
    finite = torch.isfinite(dst_x_for_src)  # a non-finite end (map or depth): no surface
    if depth is not None:
        finite &= torch.isfinite(depth)
    seg_ok &= finite[..., :-1] & finite[..., 1:]
    # Target columns of a segment: the integers in [f0, f1] inside the image, from col0 on;
    # slot m is column col0 + m and exists iff m <= room (at most W slots, whatever the span).
    col0 = torch.ceil(f0).clamp(min=0)
    room = torch.where(seg_ok, torch.floor(f1).clamp(max=w - 1) - col0, -1.0)
    parts = _segment_columns(f0, length, depth, col0, room)
    # z-buffer: the largest key wins each target pixel; among equal keys the largest source x.
    # Both reductions are maxima, so the parts (slot 0, then the few longer segments) are
    # scattered one after the other, never concatenated.
    best = torch.full((n + 1,), -math.inf, dtype=dtype, device=device)
    for idx, key, _ in parts:
        best.scatter_reduce_(0, idx, key, reduce="amax")
    out = torch.full((n + 1,), -math.inf, dtype=dtype, device=device)
    for idx, key, src in parts:
        win = key >= best.index_select(0, idx)
        out.scatter_reduce_(0, idx, torch.where(win, src, -math.inf), reduce="amax")
    hit = best[:n] != -math.inf
    return torch.where(hit, out[:n], math.nan).view(b, t, h, w), hit.view(b, t, h, w)


def _interpolate(
    frac: torch.Tensor, lo: torch.Tensor, d0: torch.Tensor | None, d1: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Source column ``lo + frac`` inside a segment and its z-buffer key (the depth
    interpolated, or the source column itself without depth)."""
    src = lo + frac
    key = src if d0 is None or d1 is None else d0 + (d1 - d0) * frac
    return src, key


def _segment_columns(
    f0: torch.Tensor, length: torch.Tensor, depth: torch.Tensor | None, col0: torch.Tensor, room: torch.Tensor
) -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """Every (segment, target column) pair of :func:`invert_row_map`, flat.

    Segment k of a row (source pixels k, k + 1) starts at target column ``f0`` and spans
    ``length`` columns; it covers the integer columns ``col0 + m`` for ``0 <= m <= room``
    (all (B, T, H, W - 1); ``room`` -1 for none). ``depth`` (B, T, H, W) or None.

    Returns:
        One ``(idx, key, src)`` per slot m, each (P_m,): the flat target pixel (B·T·H·W, a
        spare slot, with key -inf where slot 0 is no target column), the z-buffer key and
        the source column.
    """
    b, t, h, w1 = f0.shape
    w = w1 + 1
    dtype, device = f0.dtype, f0.device
    n = b * t * h * w
    # Slot 0, every segment at once (most segments cover at most one column: views
    # foreshorten).
    lo_col = torch.arange(w - 1, dtype=dtype, device=device)
    ok0 = room >= 0
    frac0 = (col0 - f0) / length
    d0 = None if depth is None else depth[..., :-1]
    d1 = None if depth is None else depth[..., 1:]
    src0, key0 = _interpolate(frac0, lo_col, d0, d1)
    row0 = torch.arange(b * t * h, device=device).view(b, t, h, 1) * w
    idx0 = torch.where(ok0, row0 + col0.clamp(max=w - 1).long(), n).reshape(-1)
    key0 = torch.where(ok0, key0, -math.inf).reshape(-1)
    src0 = src0.reshape(-1)
    # Slots m >= 1: only the few segments longer than a pixel, gathered.
    room_flat, col0_flat = room.reshape(-1), col0.reshape(-1)
    idx_parts, key_parts, src_parts = [idx0], [key0], [src0]
    cand = (room_flat >= 1).nonzero().squeeze(1)
    m = 1
    while cand.numel():
        seg, col = cand, col0_flat.index_select(0, cand) + m
        frac = (col - f0.reshape(-1).index_select(0, seg)) / length.reshape(-1).index_select(0, seg)
        lo = (seg % (w - 1)).to(dtype)
        dd0 = None if d0 is None else d0.reshape(-1).index_select(0, seg)
        dd1 = None if d1 is None else d1.reshape(-1).index_select(0, seg)
        src_m, key_m = _interpolate(frac, lo, dd0, dd1)
        idx_parts.append((seg // (w - 1)) * w + col.long())
        key_parts.append(key_m)
        src_parts.append(src_m)
        m += 1
        cand = cand[room_flat.index_select(0, cand) >= m]
    return list(zip(idx_parts, key_parts, src_parts, strict=True))


def fill_row_holes(src: torch.Tensor, hit: torch.Tensor, fallback: torch.Tensor) -> torch.Tensor:
    """Fills non-hit target pixels by interpolating the map between hits along the row.

    Beyond the last hit of a row the fallback map, shifted to meet that hit, continues
    it; a row with no hit takes the fallback map.

    Args:
        src: (..., W) map, trusted where ``hit``.
        hit: (..., W) bool, of the shape of ``src``.
        fallback: map broadcastable to ``src`` (an expanded tensor is not copied).

    Returns:
        (..., W) the map with its holes filled (a new tensor).
    """
    w = src.shape[-1]
    # Only the holes are computed (a warp's map is mostly hits); the nearest hit before and
    # after each comes from a running max / min over the row, in int32 to halve the traffic.
    holes = (~hit).reshape(-1).nonzero().squeeze(1)
    out = src.reshape(-1).clone()
    if holes.numel() == 0:
        return out.view(src.shape)
    cols = torch.arange(w, dtype=torch.int32, device=src.device)
    prev = torch.where(hit, cols, -1).cummax(dim=-1).values.reshape(-1).index_select(0, holes).long()
    nxt = torch.where(hit, cols, w).flip(-1).cummin(dim=-1).values.flip(-1)
    nxt = nxt.reshape(-1).index_select(0, holes).long()
    col = holes % w
    row = holes - col
    has_prev, has_next = prev >= 0, nxt < w
    p, n = prev.clamp(0, w - 1), nxt.clamp(0, w - 1)
    flat_src = src.reshape(-1)
    fb = fallback.expand_as(src)
    sp, sn = flat_src.index_select(0, row + p), flat_src.index_select(0, row + n)
    fp, fn, f0 = (torch.take(fb, row + k) for k in (p, n, col))
    span = (n - p).clamp_min(1).to(src.dtype)
    between = sp + (sn - sp) * (col - p).to(src.dtype) / span
    left_only = f0 + (sp - fp)
    right_only = f0 + (sn - fn)
    filled = torch.where(has_prev & has_next, between, torch.where(has_prev, left_only, right_only))
    filled = torch.where(has_prev | has_next, filled, f0)
    out.index_put_((holes,), filled)
    return out.view(src.shape)
