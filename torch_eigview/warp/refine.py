"""The 2D refinement of the row-wise maps: a tilted camera moves points along columns too.

:func:`refine_2d` inverts the forward map ``p -> p + (dx, dy)(p)`` of a seed view by
fixed-point iteration from the row-wise inverse, sampling the disparity field with
:func:`field_sampler` (one ``grid_sample`` call for every angle);
:class:`~torch_eigview.warp.maps.RowGeometry` calls it when the camera has an elevation.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F

__all__ = ["field_sampler", "refine_2d"]


def field_sampler(fields: torch.Tensor, t: int, rows: int | None = None) -> Callable[..., torch.Tensor]:
    """Bilinear sampler of per-object ``fields`` (B, F, H, W) at T·R·W points per object.

    The fields do not depend on the target angle, so one input serves all T angles: the
    points go into the grid as (B, T·R, W), one ``grid_sample`` call (border padding: these
    are maps, not images; ``align_corners=True``, the convention kornia's ``remap`` uses for
    pixel maps) instead of T stacked copies of the fields; the first ``n_fields`` fields
    (default all). The points form a (T, R, W) grid per object, R = ``rows`` (default H:
    a band of target rows samples the whole fields).
    """
    b, f, h, w = fields.shape
    sx, sy = 2.0 / max(w - 1, 1), 2.0 / max(h - 1, 1)
    h = h if rows is None else rows
    # Written in place when nothing is differentiated, one plane per coordinate: a
    # permuted view is a grid grid_sample reads as it reads an interleaved one, and each
    # plane is written in one contiguous pass (an interleaved (…, 2) grid is written with a
    # stride of 2, or assembled by a stack that copies both coordinates once more).
    planes = fields.new_empty(2, b, t, h, w)
    firsts = [fields[:, :n].contiguous() for n in range(1, f)] + [fields]

    def sample(x: torch.Tensor, y: torch.Tensor, n_fields: int = f) -> torch.Tensor:
        if torch.is_grad_enabled() and (x.requires_grad or y.requires_grad or fields.requires_grad):
            g = torch.stack([x * sx - 1, y * sy - 1], dim=-1)  # grid_sample keeps it for backward
        else:
            torch.mul(x, sx, out=planes[0]).sub_(1)
            torch.mul(y, sy, out=planes[1]).sub_(1)
            g = planes.permute(1, 2, 3, 4, 0)
        g = g.reshape(b, t * h, w, 2)  # a view for both layouts
        src = firsts[n_fields - 1]
        out = F.grid_sample(src, g, mode="bilinear", padding_mode="border", align_corners=True)
        return out.view(b, n_fields, t, h, w).transpose(1, 2)

    return sample


def refine_2d(
    src_x: torch.Tensor,
    disparity: torch.Tensor,
    coef: tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor],
    c: float,
    valid: torch.Tensor,
    own: torch.Tensor,
    iters: int = 4,
    row0: int = 0,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Inverts the 2D forward map p -> p + (dx, dy)(p) by fixed-point iteration.

    The displacement of source pixel p = (x, y) towards target angle t is linear in two
    fields that do not depend on t, the centred column G = x - c and the disparity D:
    ``dx = kx_g G + kx_d D`` and ``dy = ky_g G + ky_d D`` (``coef``). So only D is
    sampled (G is exact: its bilinear interpolation with border padding is the clamped
    column), once per object for all T angles.

    Starts from the row-wise inverse ``src_x``; a target pixel is a hit when the iteration
    lands on a valid source pixel that maps back to within half a pixel. The iteration
    stops early, with the same result, once a step leaves every coordinate unchanged.

    Args:
        src_x: (B, T, R, W) row-wise inverse, the starting column, for target rows
            ``row0 … row0 + R − 1`` (R = H: all rows).
        disparity: (B, H, W) D on the source pixel grid.
        coef: ``(kx_g, kx_d, ky_g, ky_d)``, each (1, T, 1, 1) or (B, T, 1, 1).
        c: column of the rotation axis.
        valid: (B, H, W) bool, source pixels with a trusted correspondence.
        own: (1, T, 1, 1) or (B, T, 1, 1) bool, angles at which every source pixel counts
            as valid (the seed's own angle).
        row0: the first target row of ``src_x``.

    Returns:
        ``(src_x, src_y, hit)``, each (B, T, R, W).
    """
    _, t, rows, w = src_x.shape
    h = disparity.shape[-2]
    kx_g, kx_d, ky_g, ky_d = coef
    dtype = disparity.dtype
    xx = torch.arange(w, dtype=dtype, device=disparity.device)
    yy = torch.arange(row0, row0 + rows, dtype=dtype, device=disparity.device).view(rows, 1)
    fields = torch.stack([disparity, valid.to(dtype)], dim=1)  # (B, 2, H, W)
    sample = field_sampler(fields, t, rows)

    # x - dx and y - dy with the constant parts folded per angle: a few passes per step.
    x_at = (xx + kx_g * c, kx_g, kx_d)
    y_at = (yy + ky_g * c, ky_g, ky_d)

    # Without autograd the iteration writes into buffers it reuses (the same operations,
    # so the same values): these steps are a few flops per value, so a fresh full-size
    # output per operation (its allocation and the first touch of its pages) would cost
    # about as much as the arithmetic. Two buffers per coordinate (a step reads one and
    # writes the other), the clamped column and a temporary.
    grad = torch.is_grad_enabled() and any(v.requires_grad for v in (src_x, disparity, *coef))
    bufs = None if grad else [torch.empty_like(src_x) for _ in range(6)]

    def step(base: tuple[torch.Tensor, ...], g: torch.Tensor, d: torch.Tensor, out: int = -1) -> torch.Tensor:
        if bufs is None or out < 0:
            return torch.addcmul(base[0] - base[1] * g, base[2], d, value=-1)
        part = torch.sub(base[0], torch.mul(base[1], g, out=bufs[5]), out=bufs[5])
        return torch.addcmul(part, base[2], d, value=-1, out=bufs[out])

    sx, shift = src_x, ky_g * (xx - c)
    own_d = disparity[:, None, row0 : row0 + rows]  # D at each target pixel's own place
    if bufs is None:
        sy = yy - (shift + ky_d * own_d)
    else:  # the first step writes buffers 0 and 2
        sy = torch.sub(yy, torch.mul(ky_d, own_d, out=bufs[3]).add_(shift), out=bufs[3])
    for i in range(iters):
        d = sample(sx, sy, 1)[:, :, 0]
        g = sx.clamp(0, w - 1) if bufs is None else torch.clamp(sx, 0, w - 1, out=bufs[4])
        nx, ny = step(x_at, g, d, i % 2), step(y_at, g, d, 2 + i % 2)
        # A fixed point: every further step would give the same maps again.
        done = torch.equal(nx, sx) and torch.equal(ny, sy)
        sx, sy = nx, ny
        if done:
            break
    s = sample(sx, sy)
    d = s[:, :, 0]
    # sx + dx - xx = sx - (x - dx) at the sampled disparity.
    if bufs is None:
        g = sx.clamp(0, w - 1)
        residual = (sx - step(x_at, g, d)).abs() + (sy - step(y_at, g, d)).abs()
    else:  # the halves go to the buffers that hold neither sx nor sy
        g = torch.clamp(sx, 0, w - 1, out=bufs[4])
        rx = step(x_at, g, d, 0 if bufs[0] is not sx else 1)
        ry = step(y_at, g, d, 2 if bufs[2] is not sy else 3)
        residual = torch.sub(sx, rx, out=rx).abs_().add_(torch.sub(sy, ry, out=ry).abs_())
    inside = (g == sx) & (sy == sy.clamp(0, h - 1))  # NaN is outside: NaN != NaN
    return sx, sy, ((s[:, :, 1] > 0.999) | own) & inside & (residual < 0.5)
