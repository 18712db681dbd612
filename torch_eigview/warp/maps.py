"""Target→source maps of the view warps: Eq. 2's maps, their 2D refinement, the sampler.

Convention:
    Images are (C, H, W) (batched (B, C, H, W)); x is the column, y the row; pixel
    centres are at integer coordinates. Rows never mix (the camera rotates about the
    vertical axis), so every map here is a map along rows: ``dst_x_for_src`` (forward,
    Eq. 2) gives the target column of each source pixel, ``src_x_for_dst`` (inverse) the
    source column sampled by each target pixel. Maps are in pixels, not normalized, and
    are handed to :func:`kornia.geometry.transform.remap` with ``align_corners=True``.

The maps depend only on the correspondences, so the synthesized view is linear in the
seed images: :class:`~torch_eigview.warp.base.ViewWarp` samples the seeds with them and
:mod:`torch_eigview.warp.operator` builds the same linear map as the sparse product G·C.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import torch
import torch.nn.functional as F

from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.row_maps import invert_row_map, invert_row_segments

__all__ = ["RowGeometry", "WarpMaps"]


@dataclass(frozen=True)
class WarpMaps:
    """Target→source maps and blend weights for T novel views of B objects.

    Attributes:
        src_x: (S, B, T, H, W) source column in seed view s for each target pixel.
        weight: (S, B, T, H, W) blend weight of seed view s (they sum to 1 per pixel).
        hit: (S, B, T, H, W) bool, True where seed view s sees the target pixel.
        thetas: (T,) novel angles in degrees, or (B, T): each object's own angles.
        src_y: (S, B, T, H, W) source row, or None when every target pixel samples its
            own row (the camera axis is perpendicular to the rotation axis: a pure row warp).
    """

    src_x: torch.Tensor
    weight: torch.Tensor
    hit: torch.Tensor
    thetas: torch.Tensor
    src_y: torch.Tensor | None = None

    @property
    def n_sources(self) -> int:
        return self.src_x.shape[0]


def _renormalize(weighted: torch.Tensor, share: torch.Tensor) -> torch.Tensor:
    """Silhouette-aware sampling's last step: ``weighted`` (foreground taps only) divided by
    the foreground ``share`` of the taps, 0 where that share is below 1/2 (background)."""
    return torch.where(share >= 0.5, weighted / share.clamp_min(0.5), 0.0)


def _field_sampler(fields: torch.Tensor, t: int) -> Callable[..., torch.Tensor]:
    """Bilinear sampler of per-object ``fields`` (B, F, H, W) at T·H·W points per object.

    The fields do not depend on the target angle, so one input serves all T angles: the
    points go into the grid as (B, T·H, W), one ``grid_sample`` call (border padding: these
    are maps, not images; ``align_corners=True``, the convention kornia's ``remap`` uses for
    pixel maps) instead of T stacked copies of the fields; the first ``n_fields`` fields
    (default all).
    """
    b, f, h, w = fields.shape
    sx, sy = 2.0 / max(w - 1, 1), 2.0 / max(h - 1, 1)
    # Written in place when nothing is differentiated, one plane per coordinate: a
    # permuted view is a grid grid_sample reads as fast, and each plane is written in one
    # contiguous pass (an interleaved (…, 2) grid costs about three times as much to write).
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


def _refine_2d(
    src_x: torch.Tensor,
    disparity: torch.Tensor,
    coef: tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor],
    c: float,
    valid: torch.Tensor,
    own: torch.Tensor,
    iters: int = 4,
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
        src_x: (B, T, H, W) row-wise inverse, the starting column.
        disparity: (B, H, W) D on the source pixel grid.
        coef: ``(kx_g, kx_d, ky_g, ky_d)``, each (1, T, 1, 1) or (B, T, 1, 1).
        c: column of the rotation axis.
        valid: (B, H, W) bool, source pixels with a trusted correspondence.
        own: (1, T, 1, 1) or (B, T, 1, 1) bool, angles at which every source pixel counts
            as valid (the seed's own angle).

    Returns:
        ``(src_x, src_y, hit)``, each (B, T, H, W).
    """
    _, t, h, w = src_x.shape
    kx_g, kx_d, ky_g, ky_d = coef
    dtype = disparity.dtype
    xx = torch.arange(w, dtype=dtype, device=disparity.device)
    yy = torch.arange(h, dtype=dtype, device=disparity.device).view(h, 1)
    fields = torch.stack([disparity, valid.to(dtype)], dim=1)  # (B, 2, H, W)
    sample = _field_sampler(fields, t)

    # x - dx and y - dy with the constant parts folded per angle: a few passes per step.
    x_at = (xx + kx_g * c, kx_g, kx_d)
    y_at = (yy + ky_g * c, ky_g, ky_d)

    # Without autograd the iteration writes into buffers it reuses (the same operations,
    # so the same values): a fresh full-size output costs nearly as much again as the
    # arithmetic (one product of 41 × 128 × 128 floats on one thread: 0.99 ms into a new
    # tensor, 0.57 ms into a reused one). Two buffers per coordinate (a step reads one
    # and writes the other), the clamped column and a temporary.
    grad = torch.is_grad_enabled() and any(v.requires_grad for v in (src_x, disparity, *coef))
    bufs = None if grad else [torch.empty_like(src_x) for _ in range(6)]

    def step(base: tuple[torch.Tensor, ...], g: torch.Tensor, d: torch.Tensor, out: int = -1) -> torch.Tensor:
        if bufs is None or out < 0:
            return torch.addcmul(base[0] - base[1] * g, base[2], d, value=-1)
        part = torch.sub(base[0], torch.mul(base[1], g, out=bufs[5]), out=bufs[5])
        return torch.addcmul(part, base[2], d, value=-1, out=bufs[out])

    sx, shift = src_x, ky_g * (xx - c)
    if bufs is None:
        sy = yy - (shift + ky_d * disparity[:, None])
    else:  # the first step writes buffers 0 and 2
        sy = torch.sub(yy, torch.mul(ky_d, disparity[:, None], out=bufs[3]).add_(shift), out=bufs[3])
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


@dataclass(frozen=True)
class RowGeometry:
    """Eq. 2 / Eq. 7 for one batch of novel angles, shared by both seed views.

    The tilted orthographic camera: a point (X, Y, Z), X from the rotation axis, is seen
    at ``x - c = X cos(phi) + Z sin(phi)`` and ``y = K(Y) - tilt * (Z cos(phi) - X sin(phi))``
    with ``tilt = sin(elevation)``; tilt 0 is the paper's orthographic camera, for which
    rows do not move. x follows Eq. 2 whatever the tilt.

    Attributes:
        a: (1, T, 1, 1) Eq. 2's coefficient of the first seed view, per novel angle, or
            (B, T, 1, 1) when each object has its own angles.
        b: (1, T, 1, 1) or (B, T, 1, 1), the coefficient of the second seed view.
        theta: (1, T, 1, 1) or (B, T, 1, 1), novel angles in radians.
        c: column of the rotation axis.
        alpha: angle of the second seed view in radians.
        sign: (B, 1, 1, 1) +1 or -1, the way depth points towards the camera.
        max_stretch: longest forward-map segment (pixels) still taken as one surface.
        tilt: sine of the camera's elevation.
    """

    a: torch.Tensor
    b: torch.Tensor
    theta: torch.Tensor
    c: float
    alpha: float
    sign: torch.Tensor
    max_stretch: float
    tilt: float

    def source_maps(
        self, x1: torch.Tensor, x2: torch.Tensor, valid: torch.Tensor, second: bool
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """Maps for one seed view as the source; ``x1``, ``x2`` (B, H, W) are matching columns
        in view 1 and view 2, on the pixel grid of the source view (view 2 if ``second``)."""
        c, al, th = self.c, self.alpha, self.theta
        src_x, hit = self._row_inverse(x1, x2, valid, second)
        if self.tilt == 0.0:
            return src_x, None, hit
        own = (self.a if second else self.b) == 0
        # The 2D displacement (dst_x - grid, dy) is linear in the grid's centred column G and
        # the disparity D towards the other view: x1 - c = G, x2 - c = G + D for view 1 as the
        # source, x2 - c = G, x1 - c = G + D for view 2.
        phi = al if second else 0.0
        dcos, dsin = torch.cos(th) - math.cos(phi), torch.sin(th) - math.sin(phi)
        z_d, x_d = (-math.cos(al), 1.0) if second else (1.0, 0.0)
        coef = (
            self.a + self.b - 1,
            self.a if second else self.b,
            -self.tilt * (dcos * (1 - math.cos(al)) / math.sin(al) - dsin),
            -self.tilt * (dcos * z_d / math.sin(al) - dsin * x_d),
        )
        disparity = x1 - x2 if second else x2 - x1
        return _refine_2d(src_x, disparity, coef, c, valid, own)

    def _row_inverse(
        self, x1: torch.Tensor, x2: torch.Tensor, valid: torch.Tensor, second: bool
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The row-wise inverse of :meth:`source_maps`, ``(src_x, hit)``, (B, T, H, W) each:
        from the valid pairs alone where no angle is the seed's own (:meth:`_segment_inverse`),
        the seed's own shared angles split off (:meth:`_split_own`), else on the whole grid."""
        c, al, th = self.c, self.alpha, self.theta
        b, h, w = x1.shape
        # Where the other view's coefficient vanishes (theta at this seed's own angle) the map
        # needs no correspondence: every pixel is trusted, and the seed view is reproduced.
        own = (self.a if second else self.b) == 0
        if own.shape[0] == 1 and bool(own.any()) and not bool(own.all()):
            return self._split_own(x1, x2, valid, second, own.view(-1))
        # Without a correspondence a pixel moves as a plane through the axis (Z = 0).
        scale = (math.cos(al) if second else 1.0) / torch.cos(th).clamp_min(1e-6)
        cols = torch.arange(w, dtype=x1.dtype, device=x1.device)
        fallback = (c + (cols - c) * scale).expand(b, th.shape[1], h, w)
        inverse = None if bool(own.any()) else self._segment_inverse(x1, x2, valid, fallback)
        if inverse is not None:
            return inverse
        big_x, x2c = (x1 - c)[:, None], (x2 - c)[:, None]
        big_z = (x2c - big_x * math.cos(al)) / math.sin(al)
        # Eq. 2 and the depth on the whole grid, in place where it can (the same values).
        dst_x_for_src = (self.a * big_x).add_(c).add_(self.b * x2c)
        depth = (big_z * torch.cos(th)).sub_(big_x * torch.sin(th)).mul_(self.sign)
        return invert_row_map(dst_x_for_src, valid[:, None] | own, depth, self.max_stretch, fallback=fallback)

    def _split_own(
        self, x1: torch.Tensor, x2: torch.Tensor, valid: torch.Tensor, second: bool, own: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`_row_inverse` for angles shared by the batch (``own`` (T,) bool) of which
        some, not all, are the seed's own: those on the whole grid (every pixel trusted),
        the others from the valid pairs alone (:meth:`_segment_inverse`), each angle's map
        the same as in one call over all of them."""
        b, h, w = x1.shape
        src_x = x1.new_empty(b, own.numel(), h, w)
        hit = torch.empty(src_x.shape, dtype=torch.bool, device=x1.device)
        for sel in (own.nonzero().squeeze(1), (~own).nonzero().squeeze(1)):
            part = replace(self, a=self.a[:, sel], b=self.b[:, sel], theta=self.theta[:, sel])
            sx, sh = part._row_inverse(x1, x2, valid, second)
            src_x.index_copy_(1, sel, sx)
            hit.index_copy_(1, sel, sh)
        return src_x, hit

    def _segment_inverse(
        self, x1: torch.Tensor, x2: torch.Tensor, valid: torch.Tensor, fallback: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor] | None:
        """The inverse map of :meth:`source_maps` from the forward map at the valid pixel
        pairs alone (:func:`invert_row_segments`), or None where at least half the pairs
        are valid (a textured view: the whole-grid map costs less than the gathers). An
        object on a background has most pixels invalid, and Eq. 2 is then evaluated on its
        segments only, with the same expressions, so the result equals the whole-grid one."""
        pairs = valid[..., :-1] & valid[..., 1:]
        if x1.shape[-1] < 2 or 2 * int(pairs.count_nonzero()) >= pairs.numel():
            return None
        b, h, w = x1.shape
        shape = (b, self.theta.shape[1], h, w)
        return invert_row_segments(
            *self._segment_ends(x1, x2, pairs), shape, self.max_stretch, fallback=fallback
        )

    def _segment_ends(
        self, x1: torch.Tensor, x2: torch.Tensor, pairs: torch.Tensor
    ) -> tuple[
        torch.Tensor, torch.Tensor, tuple[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]
    ]:
        """Rows, left columns, forward map and depth at both ends of every valid pixel pair
        (``pairs``, (B, H, W - 1)) for every angle: the arguments of :func:`invert_row_segments`.
        A function of its own so that its index and coefficient arrays are freed on return."""
        b, h, w = x1.shape
        t = self.theta.shape[1]
        bi, hi, ki = pairs.nonzero().unbind(1)
        # Each valid pair once per angle: (T, P), the angle's coefficients per object. The
        # arithmetic runs in place where it can: fewer large temporaries per call.
        bt = bi if t == 1 else (bi * t + torch.arange(t, device=bi.device)[:, None]).reshape(-1)
        a, b_, cos_th, sin_th = (
            v.expand(b, t, 1, 1).reshape(-1).index_select(0, bt).view(t, -1)
            for v in (self.a, self.b, torch.cos(self.theta), torch.sin(self.theta))
        )
        sign = self.sign.reshape(-1).index_select(0, bi)
        c, al = self.c, self.alpha
        left = (bi * h).add_(hi).mul_(w).add_(ki)

        def take(x: torch.Tensor, at: torch.Tensor, col: torch.Tensor) -> torch.Tensor:
            # The pixel grid of the source view is one row expanded: read from the row.
            if x.stride(0) == 0 and x.stride(1) == 0:
                return x[0, 0].index_select(0, col)
            return x.reshape(-1).index_select(0, at)

        def ends(at: torch.Tensor, col: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            # Eq. 2's expressions of source_maps, operation for operation.
            big_x, x2c = take(x1, at, col).sub_(c), take(x2, at, col).sub_(c)
            big_z = big_x * math.cos(al)
            torch.sub(x2c, big_z, out=big_z).div_(math.sin(al))
            dst = (a * big_x).add_(c).add_(b_ * x2c)
            depth = (big_z * cos_th).sub_(big_x * sin_th).mul_(sign)
            return dst.reshape(-1), depth.reshape(-1)

        (f0, d0), (f1, d1) = ends(left, ki), ends(left + 1, ki + 1)
        row = (bt.view(t, -1) * h).add_(hi).reshape(-1)
        return row, ki.repeat(t), (f0, f1), (d0, d1)

    def maps(
        self,
        correspondence: Correspondence,
        thetas: torch.Tensor,
        share_of_second: torch.Tensor,
        n_sources: int,
    ) -> WarpMaps:
        """Both seed views' maps (or view 1's alone) and their blend weights.

        Args:
            correspondence: (B, H, W) correspondences between the seed views.
            thetas: (T,) or (B, T) novel angles in degrees, stored in the result.
            share_of_second: (1, T, 1, 1) or (B, T, 1, 1) the second seed's weight where
                both see a pixel.
            n_sources: 2 to blend both seed views, 1 to warp view 1 alone.

        Returns:
            :class:`WarpMaps` with S = ``n_sources``; ``src_y`` is None unless ``tilt`` is set.
        """
        d12 = correspondence.disparity_12
        cols = torch.arange(d12.shape[-1], dtype=d12.dtype, device=d12.device).expand_as(d12)
        # Source view 1: x1 is the pixel grid, x2 its match. Source view 2: the other way.
        src1, srcy1, hit1 = self.source_maps(cols, cols + d12, correspondence.valid_12, second=False)
        if n_sources == 1:
            sy = None if srcy1 is None else srcy1[None]
            return WarpMaps(src1[None], torch.ones_like(src1)[None], hit1[None], thetas, sy)
        src2, srcy2, hit2 = self.source_maps(
            cols + correspondence.disparity_21, cols, correspondence.valid_21, second=True
        )
        # Where both views see a pixel the nearer one in angle weighs more; where one is
        # occluded the other is used alone; where neither sees it, the angular weights.
        # Written in place: the stacked weights need no copies of the two halves. Both or
        # neither seeing a pixel is hit1 == hit2.
        weight = src1.new_empty((2, *src1.shape))
        torch.where(hit1 == hit2, (1 - share_of_second).expand_as(src1), hit1.to(d12.dtype), out=weight[0])
        torch.sub(1, weight[0], out=weight[1])
        src_y = None if srcy1 is None or srcy2 is None else torch.stack([srcy1, srcy2])
        return WarpMaps(torch.stack([src1, src2]), weight, torch.stack([hit1, hit2]), thetas, src_y)
