"""Inverting a forward map along rows: the source column each target pixel samples.

The orthographic camera rotating about the vertical axis moves pixels along their rows
(Eq. 2), so a seed view's forward map ``x3(x1)`` is inverted row by row:
:func:`invert_row_map` scans the map's segments (z-buffered where the surface folds),
:func:`invert_row_segments` does the same from the ends of the candidate segments alone
(a map that is mostly background), and :func:`fill_row_holes` continues the inverse over
target pixels no segment covers.
:class:`~torch_eigview.warp.novel_view.NovelViewWarp` builds its maps with both.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

__all__ = ["fill_row_holes", "invert_row_map", "invert_row_segments"]


def invert_row_map(
    dst_x_for_src: torch.Tensor,
    valid: torch.Tensor,
    depth: torch.Tensor | None,
    max_stretch: float = math.inf,
    *,
    fallback: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Inverts a forward map along rows: the source column sampled by each target pixel.

    Each pair of neighbouring valid source pixels (k, k + 1) whose targets keep their
    order and lie at most ``max_stretch`` pixels apart is a segment mapped linearly onto
    the target row; every integer target column it covers takes the linearly inverted
    source column. Segments whose order flips are surface turned away from the novel
    camera; where segments overlap the one nearest the camera (largest ``depth``) wins,
    like a z-buffer. A segment with a non-finite end (map or depth) is left out.

    Only the segments that pass these tests are rasterized (a view's background has
    none), all rows, angles and objects of the batch in one flat pass.

    Args:
        dst_x_for_src: (B, T, H, W) forward map x3(x1) in pixels.
        valid: (B, H, W) or (B, T, H, W) bool, source pixels with a trusted correspondence.
        depth: (B, T, H, W) depth towards the novel camera, or None (ties: largest source x).
        max_stretch: longest segment (target pixels) still taken as one surface.
        fallback: map broadcastable to (B, T, H, W), or None. Given, the holes are filled
            at once (:func:`fill_row_holes` with it), which spares a pass writing NaN.

    Returns:
        ``(src_x_for_dst, hit)``, (B, T, H, W) each; ``src_x_for_dst`` is NaN where
        ``hit`` is False, or, with ``fallback``, filled there.
    """
    b, t, h, w = dst_x_for_src.shape
    dtype, device = dst_x_for_src.dtype, dst_x_for_src.device
    f0, f1 = dst_x_for_src[..., :-1], dst_x_for_src[..., 1:]
    length = f1 - f0
    valid = valid[:, None] if valid.ndim == 3 else valid
    seg_ok = length > 0
    seg_ok &= length <= max_stretch
    seg_ok &= valid[..., :-1] & valid[..., 1:]
    n_seg = int(seg_ok.count_nonzero())
    fields = [dst_x_for_src] if depth is None else [dst_x_for_src, depth]
    parts: Parts = []
    if n_seg and 2 * n_seg >= seg_ok.numel():
        parts = _dense_columns(fields, seg_ok, length)
    elif n_seg:
        # (row, k) pairs straight from the 2-D nonzero: no integer division of flat indices.
        row, k = seg_ok.reshape(-1, w - 1).nonzero().unbind(1)
        left = row * w + k  # source pixel k of the segment, flat in (B, T, H, W)
        ends = [
            (v.reshape(-1).index_select(0, left), v.reshape(-1).index_select(0, left + 1)) for v in fields
        ]
        parts = _sparse_columns(row, k, ends, None, w, b * t * h * w)
    return _z_buffer(parts, (b, t, h, w), dtype, device, fallback)


def invert_row_segments(
    row: torch.Tensor,
    k: torch.Tensor,
    dst_ends: tuple[torch.Tensor, torch.Tensor],
    depth_ends: tuple[torch.Tensor, torch.Tensor] | None,
    shape: tuple[int, int, int, int],
    max_stretch: float = math.inf,
    *,
    fallback: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`invert_row_map` given its candidate segments alone, for a map that is mostly
    background: the caller evaluates the forward map at the ends of the segments whose two
    source pixels are valid, never on the whole grid.

    The same segments pass (order kept, at most ``max_stretch`` long, finite ends), and
    the result equals :func:`invert_row_map`'s on the full maps bit for bit.

    Args:
        row: (P,) int64 row of each segment in the B·T·H rows of ``shape``.
        k: (P,) int64 its left source column (the right one is k + 1).
        dst_ends: ``(f0, f1)``, each (P,), the forward map at columns k and k + 1.
        depth_ends: ``(d0, d1)``, each (P,), the depth there, or None.
        shape: ``(B, T, H, W)`` of the maps.
        max_stretch: longest segment (target pixels) still taken as one surface.
        fallback: as :func:`invert_row_map`'s.

    Returns:
        ``(src_x_for_dst, hit)``, (B, T, H, W) each, as :func:`invert_row_map` returns them.
    """
    f0, f1 = dst_ends
    sizes = {tuple(v.shape) for v in (row, k, f0, f1, *(depth_ends or ()))}
    if len(sizes) != 1 or len(next(iter(sizes))) != 1:
        raise ValueError(f"row, k and the ends must all have one shape (P,), got shapes {sorted(sizes)}")
    if len(shape) != 4:
        raise ValueError(f"shape must be (B, T, H, W), got {tuple(shape)}")
    ends = [dst_ends] if depth_ends is None else [dst_ends, depth_ends]
    length = f1 - f0
    keep = (length > 0) & (length <= max_stretch)
    parts = _sparse_columns(row, k, ends, keep, shape[-1], math.prod(shape), length)
    del keep, length
    return _z_buffer(parts, tuple(shape), f0.dtype, f0.device, fallback)


Parts = list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]


def _z_buffer(
    parts: Parts,
    shape: tuple[int, ...],
    dtype: torch.dtype,
    device: torch.device,
    fallback: torch.Tensor | None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The winner of each target pixel among the ``parts`` of :func:`_columns`: its source
    column (NaN, or ``fallback`` filled, where none covers it) and the hit mask, ``shape``
    each. Empties ``parts``: their tensors are freed before the fill (a lower peak)."""
    n = math.prod(shape)
    out, hit = _winners(parts, n, dtype, device)
    parts.clear()
    hit = hit.view(shape)
    if fallback is not None:  # the fill reads the hits' columns only, never the holes' -inf
        return fill_row_holes(out[:n].view(shape), hit, fallback), hit
    return torch.where(hit, out[:n].view(shape), math.nan), hit


def _winners(
    parts: Parts, n: int, dtype: torch.dtype, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor]:
    """z-buffer: the largest key wins each of the ``n`` target pixels; among equal keys the
    largest source x. Returns the (n + 1,) winning source columns (-inf where none; the
    last is the spare pixel) and the (n,) hit mask."""
    # Both reductions are maxima, so the parts (one per slot) are scattered one after the
    # other, never concatenated.
    best = torch.full((n + 1,), -math.inf, dtype=dtype, device=device)
    for idx, key, _ in parts:
        best.scatter_reduce_(0, idx, key, reduce="amax")
    out = torch.full((n + 1,), -math.inf, dtype=dtype, device=device)
    for idx, key, src in parts:
        win = key >= best.index_select(0, idx)
        out.scatter_reduce_(0, idx, torch.where(win, src, -math.inf), reduce="amax")
    return out, best[:n] != -math.inf


def _dense_columns(fields: list[torch.Tensor], seg_ok: torch.Tensor, length: torch.Tensor) -> Parts:
    """:func:`_columns` when most segments pass (a view's object fills it): slot 0 on views
    of the whole map, a refused segment sending key -inf to a spare pixel; ``length`` the
    segments' lengths, (B, T, H, W - 1)."""
    b, t, h, w = fields[0].shape
    dtype, device, w1 = fields[0].dtype, fields[0].device, w - 1
    ends = [(v[..., :-1], v[..., 1:]) for v in fields]
    k = torch.arange(w1, dtype=dtype, device=device)
    row_start = torch.arange(b * t * h, device=device).view(b, t, h, 1) * w
    # A non-finite end (map or depth) is no surface; a finite sum of the maps proves every
    # value finite (as in _sparse_columns), the common case's shortcut.
    ok = seg_ok
    if not math.isfinite(float(sum(v.sum() for v in fields))):
        finite = _all_finite(fields)
        ok = seg_ok & finite[..., :-1] & finite[..., 1:]

    def locate(cand: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return (cand % w1).to(dtype), (cand // w1) * w

    return _columns(ends, k, row_start, ok, w, fields[0].numel(), locate, length)


def _sparse_columns(
    row: torch.Tensor,
    k_int: torch.Tensor,
    ends: list[tuple[torch.Tensor, torch.Tensor]],
    keep: torch.Tensor | None,
    w: int,
    n: int,
    length: torch.Tensor | None = None,
) -> Parts:
    """:func:`_columns` when few segments pass (a background around the object): only the
    segments in (``row``, ``k_int``), their ``ends`` gathered; ``keep`` the ones that pass
    the order and length tests (None: all); ``n`` the spare pixel, B·T·H·W; ``length``
    the segments' lengths where the caller has them."""
    f0 = ends[0][0]
    row_start = row * w
    k = k_int.to(f0.dtype)
    gathered = [v for pair in ends for v in pair]
    # A finite sum of the ends proves every end finite (a NaN or an infinity would carry
    # into it; an overflow only costs the elementwise test), the common case's shortcut.
    ok = None if math.isfinite(float(sum(v.sum() for v in gathered))) else _all_finite(gathered)
    if keep is not None:
        ok = keep if ok is None else ok & keep

    def locate(cand: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return k.index_select(0, cand), row_start.index_select(0, cand)

    return _columns(ends, k, row_start, ok, w, n, locate, length)


def _columns(
    ends: list[tuple[torch.Tensor, torch.Tensor]],
    k: torch.Tensor,
    row_start: torch.Tensor,
    ok: torch.Tensor | None,
    w: int,
    n: int,
    locate: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]],
    length: torch.Tensor | None = None,
) -> Parts:
    """Every (segment, target column) pair of :func:`invert_row_map`, flat.

    Segment k of a row (source pixels k, k + 1) starts at target column ``f0 = dst[k]``
    and ends at ``f1 = dst[k + 1]``; it covers the integer columns ``col0 + m`` inside the
    image, ``col0 = ceil(f0)`` clamped at 0, for ``0 <= m <= room``. Slot 0 takes every
    segment (a refused one, ``ok`` False, sends key -inf to the spare pixel ``n``); slots
    m >= 1 gather the few segments that reach them (views foreshorten).

    Args:
        ends: ``(f0, f1)`` of the map and, optionally, ``(d0, d1)`` of the depth, each
            over the segments (any shape, the shape of ``k`` broadcast with ``row_start``).
        k: the segments' left source column (float); ``row_start`` their row's first
            flat pixel in B·T·H·W.
        ok: bool, the segments that pass, or None (all).
        w: the row length W; ``n``: the spare pixel, B·T·H·W.
        locate: flat indices of the segments (``cand``) → their ``(k, row_start)``.
        length: ``f1 - f0`` where the caller has it, or None (computed here).

    Returns:
        One ``(idx, key, src)`` per slot m, each (P_m,): the flat target pixel (or the
        spare pixel), the z-buffer key and the source column.
    """
    (f0, f1), dd = ends[0], (ends[1] if len(ends) > 1 else None)
    # In place where it can: fewer large temporaries per call, the same values.
    length = f1 - f0 if length is None else length
    col0 = torch.ceil(f0).clamp_(min=0)
    room = torch.floor(f1).clamp_(max=w - 1).sub_(col0)
    if ok is not None:
        room.masked_fill_(~ok, -1.0)
    ok0 = room >= 0
    src0, key0 = _interpolate((col0 - f0).div_(length), k, dd)
    idx0 = col0.clamp(max=w - 1).long().add_(row_start).masked_fill_(~ok0, n).reshape(-1)
    parts = [(idx0, torch.where(ok0, key0, -math.inf).reshape(-1), src0.reshape(-1))]
    # Fresh tensors, so flat views; the ends are read at the candidates with torch.take,
    # since on the dense path they are strided views of the maps (no copy of them).
    c0_flat, len_flat, room_flat = (v.reshape(-1) for v in (col0, length, room))
    cand = (room_flat >= 1).nonzero().squeeze(1)
    m = 1
    while cand.numel():
        c0, ln, s0 = c0_flat.index_select(0, cand), len_flat.index_select(0, cand), torch.take(f0, cand)
        col = c0 + m
        lo, start = locate(cand)
        sel = None if dd is None else (torch.take(dd[0], cand), torch.take(dd[1], cand))
        src_m, key_m = _interpolate((col - s0) / ln, lo, sel)
        parts.append((start + col.long(), key_m, src_m))
        m += 1
        cand = cand[room_flat.index_select(0, cand) >= m]
    return parts


def _all_finite(values: list[torch.Tensor]) -> torch.Tensor:
    """Elementwise: every one of ``values`` (of one shape) is finite."""
    out = torch.isfinite(values[0])
    for v in values[1:]:
        out &= torch.isfinite(v)
    return out


def _interpolate(
    frac: torch.Tensor, lo: torch.Tensor, depth: tuple[torch.Tensor, torch.Tensor] | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Source column ``lo + frac`` inside a segment and its z-buffer key (the depth of its
    ends ``depth`` interpolated, or the source column itself without depth)."""
    key = None if depth is None else (depth[1] - depth[0]).mul_(frac).add_(depth[0])
    src = frac.add_(lo)  # frac is the caller's temporary
    return src, src if key is None else key


def fill_row_holes(src: torch.Tensor, hit: torch.Tensor, fallback: torch.Tensor) -> torch.Tensor:
    """Fills non-hit target pixels by interpolating the map between hits along the row.

    Beyond the last hit of a row the fallback map, shifted to meet that hit, continues
    it (likewise before the first hit); a row with no hit takes the fallback map.

    A row splits into its exterior, before its first hit and after its last, where the
    map is the fallback plus one shift per side, and its interior, from the first hit to
    the last, where holes interpolate between their neighbouring hits. The exterior is a
    few whole-grid passes (a running sum of the shifts); the interior holes are found from
    the row's changes between hit and hole (a gap opens where a hit is followed by a hole
    and closes where a hole is followed by a hit), and only they are gathered: no scan over
    every pixel of a row's interior, hits included.

    Args:
        src: (..., W) map, trusted where ``hit`` (any value elsewhere, NaN included).
        hit: (..., W) bool, of the shape of ``src``.
        fallback: map broadcastable to ``src`` (an expanded tensor is not copied).

    Returns:
        (..., W) the map with its holes filled (a new tensor).
    """
    shape, w = src.shape, src.shape[-1]
    if int(hit.count_nonzero()) == hit.numel():
        return src.clone()
    src_rows, hit_rows = src.reshape(-1, w), hit.reshape(-1, w)
    # First and last hit of each row as maxima over the row, in a small integer type (W and
    # -1 on a row without one, whose shifts are 0 and whose pixels are all exterior).
    small = torch.int16 if w < 2**15 - 1 else torch.int64
    as_int = hit_rows.to(small)
    cols = torch.arange(w, dtype=small, device=src.device)
    first = w - (as_int * (w - cols)).amax(dim=-1, keepdim=True)
    last = (as_int * (cols + 1)).amax(dim=-1, keepdim=True) - 1
    del as_int
    ends = torch.cat([first, last], dim=1).clamp(0, w - 1).long()
    # The exterior's shift, map minus fallback at the nearest hit; 0 on a row without hits.
    fb_ends = fallback.expand(shape).gather(-1, ends.view(*shape[:-1], 2)).view(-1, 2)
    shift = torch.where(last >= 0, src_rows.gather(1, ends) - fb_ends, 0.0)
    # The shift of every pixel (s0 before the first hit, 0 inside, s1 after the last) as a
    # running sum of its steps: s0 at column 0, -s0 at the first hit, s1 after the last
    # (on the last hit itself where that is the last column: a hit keeps its own value).
    # Each partial sum is s0, 0 or s1 exactly, and a scan costs less than per-pixel masks.
    steps = src.new_zeros(src_rows.shape[0], w, dtype=torch.promote_types(src.dtype, fallback.dtype))
    steps[:, 0] = shift[:, 0]
    steps.scatter_add_(1, ends[:, :1], -shift[:, :1])
    steps.scatter_add_(1, (ends[:, 1:] + 1).clamp_(max=w - 1), shift[:, 1:])
    out = steps.cumsum_(dim=1).view(shape).add_(fallback)
    del steps
    if torch.is_grad_enabled() and (src.requires_grad or fallback.requires_grad):
        out = torch.where(hit, src, out).contiguous()  # differentiable: no out= argument
    else:
        torch.where(hit, src, out, out=out)
    _fill_gaps(out.view(-1, w), src_rows, hit_rows, first.view(-1), last.view(-1))
    return out


def _fill_gaps(
    out: torch.Tensor, src: torch.Tensor, hit: torch.Tensor, first: torch.Tensor, last: torch.Tensor
) -> None:
    """Writes into ``out`` (R, W) the holes between two hits of a row: the linear
    interpolation of the hits on either side. ``src`` and ``hit`` are (R, W); ``first`` and
    ``last`` (R,) each row's first and last hit."""
    w = src.shape[1]
    # A row's changes between hit and hole alternate: its leading gap closes at its first
    # hit and its trailing gap opens at its last (both exterior); the others pair up, each
    # gap opened (at its hit p) and then closed (at its last hole, n - 1).
    change = (hit[:, 1:] ^ hit[:, :-1]).nonzero()  # (row, k): columns k and k + 1 differ
    row, k = change.unbind(1)
    keep = (k != last.index_select(0, row)) & (k + 1 != first.index_select(0, row))
    gaps = change[keep].view(-1, 2, 2)  # (gap, open | close, row | k)
    if gaps.shape[0] == 0:
        return
    row, p = gaps[:, 0].unbind(1)
    n = gaps[:, 1, 1] + 1
    count = n - p - 1
    total = int(count.sum())
    # Per gap first (its hits, their difference, its span), then spread over its holes:
    # the per-hole work is a few gathers and the interpolation itself.
    flat = src.reshape(-1)
    at = row * w + p  # the hit before each gap, flat
    sp = flat.index_select(0, at)
    # Column differences in integers (exact in any float dtype, half precision included).
    diff, span = flat.index_select(0, at + (n - p)) - sp, (n - p).to(src.dtype)
    g = torch.repeat_interleave(torch.arange(count.numel(), device=src.device), count, output_size=total)
    step = torch.arange(1, total + 1, device=src.device).sub_((count.cumsum(0) - count).index_select(0, g))
    # sp + (sn - sp) * step / span, hole by hole.
    value = (
        (diff.index_select(0, g) * step.to(src.dtype))
        .div_(span.index_select(0, g))
        .add_(sp.index_select(0, g))
    )
    out.view(-1).index_copy_(0, at.index_select(0, g).add_(step), value)
