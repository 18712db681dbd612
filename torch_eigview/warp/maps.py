"""Target→source maps of the view warps: Eq. 2's maps, their 2D refinement, the sampler.

Convention:
    Images are (C, H, W) (batched (B, C, H, W)); x is the column, y the row; pixel
    centres are at integer coordinates. Rows never mix (the camera rotates about the
    vertical axis), so every map here is a map along rows: ``dst_x_for_src`` (forward,
    Eq. 2) gives the target column of each source pixel, ``src_x_for_dst`` (inverse) the
    source column sampled by each target pixel. Maps are in pixels, not normalized, and
    are sampled as :func:`kornia.geometry.transform.remap` samples them with
    ``align_corners=True`` (:class:`~torch_eigview.warp.base.ViewWarp`).

The maps depend only on the correspondences, so the synthesized view is linear in the
seed images: :class:`~torch_eigview.warp.base.ViewWarp` samples the seeds with them and
:mod:`torch_eigview.warp.operator` builds the same linear map as the sparse product G·C.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch

from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.row_maps import invert_row_map, invert_row_segments
from torch_eigview.warp.refine import refine_2d

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
        row0: the first target row the maps hold: H here may be a band of the views' rows,
            ``row0 … row0 + H − 1`` (maps built with ``support``, :meth:`RowGeometry.maps`);
            every other row of the views samples only rows that are zero in the seeds.
    """

    src_x: torch.Tensor
    weight: torch.Tensor
    hit: torch.Tensor
    thetas: torch.Tensor
    src_y: torch.Tensor | None = None
    row0: int = 0

    @property
    def n_sources(self) -> int:
        return self.src_x.shape[0]


def _renormalize(weighted: torch.Tensor, share: torch.Tensor) -> torch.Tensor:
    """Silhouette-aware sampling's last step: ``weighted`` (foreground taps only) divided by
    the foreground ``share`` of the taps, 0 where that share is below 1/2 (background)."""
    return torch.where(share >= 0.5, weighted / share.clamp_min(0.5), 0.0)


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
        self,
        x1: torch.Tensor,
        x2: torch.Tensor,
        valid: torch.Tensor,
        second: bool,
        rows: tuple[int, int] | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """Maps for one seed view as the source; ``x1``, ``x2`` (B, H, W) are matching columns
        in view 1 and view 2, on the pixel grid of the source view (view 2 if ``second``).
        ``rows``: (first, end) of the target rows to build, default all: the maps are then
        (B, T, end − first, W), each row as in the whole-grid maps."""
        r0, r1 = (0, x1.shape[-2]) if rows is None else rows
        band = slice(r0, r1)
        src_x, hit = self._row_inverse(x1[:, band], x2[:, band], valid[:, band], second)
        if self.tilt == 0.0:
            return src_x, None, hit
        own = (self.a if second else self.b) == 0
        disparity = x1 - x2 if second else x2 - x1
        return refine_2d(src_x, disparity, self._tilt_coefficients(second), self.c, valid, own, row0=r0)

    def _tilt_coefficients(
        self, second: bool
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(kx_g, kx_d, ky_g, ky_d)`` of :func:`~torch_eigview.warp.refine.refine_2d` for one seed view as the source."""
        al, th = self.alpha, self.theta
        # The 2D displacement (dst_x - grid, dy) is linear in the grid's centred column G and
        # the disparity D towards the other view: x1 - c = G, x2 - c = G + D for view 1 as the
        # source, x2 - c = G, x1 - c = G + D for view 2.
        phi = al if second else 0.0
        dcos, dsin = torch.cos(th) - math.cos(phi), torch.sin(th) - math.sin(phi)
        z_d, x_d = (-math.cos(al), 1.0) if second else (1.0, 0.0)
        return (
            self.a + self.b - 1,
            self.a if second else self.b,
            -self.tilt * (dcos * (1 - math.cos(al)) / math.sin(al) - dsin),
            -self.tilt * (dcos * z_d / math.sin(al) - dsin * x_d),
        )

    def row_band(self, correspondence: Correspondence, support: torch.Tensor) -> tuple[int, int]:
        """The target rows that can sample a ``support`` row: (first, end).

        A target pixel's source row lies within :meth:`_row_reach` rows of its own, so a
        row farther than that (and a bilinear tap) from every support row samples none.

        Args:
            correspondence: (B, H, W) the correspondences the maps are built from.
            support: (B, H) bool, the seed rows holding a pixel that is not zero (for
                either seed view).

        Returns:
            ``(first, end)`` of the rows to build: all of them, ``(0, H)``, where the reach
            is not finite; the first row alone where no row is support (the views are 0).
        """
        h = support.shape[-1]
        found = support.any(dim=0).nonzero()
        if found.numel() == 0:
            return 0, min(h, 1)
        reach = self._row_reach(correspondence)
        if not math.isfinite(reach):
            return 0, h
        # One row for the bilinear tap below a fractional row, one for the rounding of the
        # grid's normalization.
        margin = math.ceil(reach) + 2
        return max(0, int(found[0]) - margin), min(h, int(found[-1]) + margin + 1)

    def _row_reach(self, correspondence: Correspondence) -> float:
        """An upper bound on how many rows a target pixel's source row lies from its own:
        0 for the pure row warp, else the largest ``|ky_g (g − c) + ky_d d|`` of
        :func:`~torch_eigview.warp.refine.refine_2d`'s rows (g a column of the image, d a bilinear sample of the
        disparity, so within its extremes) over both sources and every angle."""
        if self.tilt == 0.0:
            return 0.0
        w = correspondence.shape[-1]
        span = max(abs(self.c), abs(w - 1 - self.c))
        reach = 0.0
        for second, d in ((False, correspondence.disparity_12), (True, correspondence.disparity_21)):
            _, _, ky_g, ky_d = self._tilt_coefficients(second)
            largest = float(d.abs().amax()) if d.numel() else 0.0
            here = float((ky_g.abs() * span + ky_d.abs() * largest).amax())
            if not math.isfinite(here):  # a non-finite disparity: no bound (max() would drop a NaN)
                return math.inf
            reach = max(reach, here)
        return reach

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
        support: torch.Tensor | None = None,
    ) -> WarpMaps:
        """Both seed views' maps (or view 1's alone) and their blend weights.

        Args:
            correspondence: (B, H, W) correspondences between the seed views.
            thetas: (T,) or (B, T) novel angles in degrees, stored in the result.
            share_of_second: (1, T, 1, 1) or (B, T, 1, 1) the second seed's weight where
                both see a pixel.
            n_sources: 2 to blend both seed views, 1 to warp view 1 alone.
            support: optional (B, H) bool, the seed rows holding a pixel that is not zero
                (either seed): the maps then hold the band of target rows that can sample
                one (:meth:`row_band`; ``WarpMaps.row0`` its first row), each row as in
                the whole-grid maps.

        Returns:
            :class:`WarpMaps` with S = ``n_sources``; ``src_y`` is None unless ``tilt`` is set.
        """
        d12 = correspondence.disparity_12
        cols = torch.arange(d12.shape[-1], dtype=d12.dtype, device=d12.device).expand_as(d12)
        rows = None if support is None else self.row_band(correspondence, support)
        row0 = 0 if rows is None else rows[0]
        # Source view 1: x1 is the pixel grid, x2 its match. Source view 2: the other way.
        src1, srcy1, hit1 = self.source_maps(cols, cols + d12, correspondence.valid_12, False, rows)
        if n_sources == 1:
            sy = None if srcy1 is None else srcy1[None]
            return WarpMaps(src1[None], torch.ones_like(src1)[None], hit1[None], thetas, sy, row0)
        src2, srcy2, hit2 = self.source_maps(
            cols + correspondence.disparity_21, cols, correspondence.valid_21, True, rows
        )
        # Where both views see a pixel the nearer one in angle weighs more; where one is
        # occluded the other is used alone; where neither sees it, the angular weights.
        # Written in place: the stacked weights need no copies of the two halves. Both or
        # neither seeing a pixel is hit1 == hit2.
        weight = src1.new_empty((2, *src1.shape))
        torch.where(hit1 == hit2, (1 - share_of_second).expand_as(src1), hit1.to(d12.dtype), out=weight[0])
        torch.sub(1, weight[0], out=weight[1])
        src_y = None if srcy1 is None or srcy2 is None else torch.stack([srcy1, srcy2])
        return WarpMaps(torch.stack([src1, src2]), weight, torch.stack([hit1, hit2]), thetas, src_y, row0)
