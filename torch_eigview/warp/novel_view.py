"""Novel-view synthesis for the orthographic camera: forward maps, their inverse, the warp.

Convention:
    Images are (C, H, W) (batched (B, C, H, W)); x is the column, y the row; pixel
    centres are at integer coordinates. Rows never mix (the camera rotates about the
    vertical axis), so every map here is a map along rows: ``dst_x_for_src`` (forward,
    Eq. 2) gives the target column of each source pixel, ``src_x_for_dst`` (inverse) the
    source column sampled by each target pixel. Maps are in pixels, not normalized, and
    are handed to :func:`kornia.geometry.transform.remap` with ``align_corners=True``.

The synthesized view is linear in the seed images: bilinear (tent, Eq. 4) sampling with
weights that depend only on the correspondences, blended over the two seed views with
weights that also depend only on the correspondences. :mod:`torch_eigview.warp.operator`
builds the same linear map as the sparse product G·C of Eqs. 3–6.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from kornia.geometry.transform import remap

from torch_eigview.check import as_angle_tensor, check_alpha, check_float_tensor, check_ndim, check_number
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.pose import affine_coefficients, orthographic_coefficients
from torch_eigview.geometry.row_maps import fill_row_holes, invert_row_map

__all__ = ["BLENDS", "NovelViewWarp", "WarpMaps"]

#: How two seed views that both see a target pixel share it (:class:`NovelViewWarp`'s ``blend``).
BLENDS = ("linear", "nearest")


@dataclass(frozen=True)
class WarpMaps:
    """Target→source maps and blend weights for T novel views of B objects.

    Attributes:
        src_x: (S, B, T, H, W) source column in seed view s for each target pixel.
        weight: (S, B, T, H, W) blend weight of seed view s (they sum to 1 per pixel).
        hit: (S, B, T, H, W) bool, True where seed view s sees the target pixel.
        thetas: (T,) novel angles in degrees.
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


def _sampler(fields: torch.Tensor) -> Callable[..., torch.Tensor]:
    """Bilinear sampler of ``fields`` (B, T, F, H, W) at pixel coordinates (B, T, H, W).

    These are maps, not images: sampled with ``grid_sample`` directly (border padding,
    ``align_corners=True``, the convention kornia's ``remap`` uses for pixel maps), the
    first ``n_fields`` of the F fields (default all) in one call.
    """
    b, t, f, h, w = fields.shape
    flat = fields.reshape(b * t, f, h, w)
    sx, sy = 2.0 / max(w - 1, 1), 2.0 / max(h - 1, 1)
    grid = fields.new_empty(b, t, h, w, 2)  # written in place on every call

    def sample(x: torch.Tensor, y: torch.Tensor, n_fields: int = f) -> torch.Tensor:
        if torch.is_grad_enabled() and (x.requires_grad or y.requires_grad or flat.requires_grad):
            # out= does not differentiate, and grid_sample keeps its grid for the backward
            # pass, so a differentiated call gets a grid of its own.
            g = torch.stack([x * sx - 1, y * sy - 1], dim=-1)
        else:
            torch.mul(x, sx, out=grid[..., 0]).sub_(1)
            torch.mul(y, sy, out=grid[..., 1]).sub_(1)
            g = grid
        src = flat if n_fields == f else flat[:, :n_fields]
        out = F.grid_sample(
            src, g.view(b * t, h, w, 2), mode="bilinear", padding_mode="border", align_corners=True
        )
        return out.view(b, t, n_fields, h, w)

    return sample


def _renormalize(weighted: torch.Tensor, share: torch.Tensor) -> torch.Tensor:
    """Silhouette-aware sampling's last step: ``weighted`` (foreground taps only) divided by
    the foreground ``share`` of the taps, 0 where that share is below 1/2 (background)."""
    return torch.where(share >= 0.5, weighted / share.clamp_min(0.5), 0.0)


@dataclass(frozen=True)
class _Geometry:
    """Eq. 2 / Eq. 7 for one batch of novel angles, shared by both seed views.

    The tilted orthographic camera: a point (X, Y, Z), X from the rotation axis, is seen
    at ``x - c = X cos(phi) + Z sin(phi)`` and ``y = K(Y) - tilt * (Z cos(phi) - X sin(phi))``
    with ``tilt = sin(elevation)``; tilt 0 is the paper's orthographic camera, for which
    rows do not move. x follows Eq. 2 whatever the tilt.
    """

    a: torch.Tensor  # (1, T, 1, 1)
    b: torch.Tensor
    theta: torch.Tensor  # (1, T, 1, 1) radians
    c: float
    alpha: float  # radians
    sign: torch.Tensor  # (B, 1, 1, 1)
    max_stretch: float
    tilt: float

    def source_maps(
        self, x1: torch.Tensor, x2: torch.Tensor, valid: torch.Tensor, second: bool
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """Maps for one seed view as the source; ``x1``, ``x2`` (B, H, W) are matching columns
        in view 1 and view 2, on the pixel grid of the source view (view 2 if ``second``)."""
        c, al, th = self.c, self.alpha, self.theta
        big_x = (x1 - c)[:, None]
        big_z = ((x2 - c)[:, None] - big_x * math.cos(al)) / math.sin(al)
        dst_x_for_src = c + self.a * (x1 - c)[:, None] + self.b * (x2 - c)[:, None]
        depth = self.sign * (big_z * torch.cos(th) - big_x * torch.sin(th))
        # Where the other view's coefficient vanishes (theta at this seed's own angle) the map
        # needs no correspondence: every pixel is trusted, and the seed view is reproduced.
        other = self.a if second else self.b
        valid = valid[:, None] | (other == 0)
        src_x, hit = invert_row_map(dst_x_for_src, valid, depth, self.max_stretch)
        # Without a correspondence a pixel moves as a plane through the axis (Z = 0).
        scale = (math.cos(al) if second else 1.0) / torch.cos(th).clamp_min(1e-6)
        cols = torch.arange(x1.shape[-1], dtype=x1.dtype, device=x1.device)
        src_x = fill_row_holes(src_x, hit, (c + (cols - c) * scale).expand_as(src_x))
        if self.tilt == 0.0:
            return src_x, None, hit
        phi = al if second else 0.0
        dy = -self.tilt * (big_z * (torch.cos(th) - math.cos(phi)) - big_x * (torch.sin(th) - math.sin(phi)))
        grid = x2 if second else x1
        return _refine_2d(src_x, dst_x_for_src - grid[:, None], dy, valid)


def _refine_2d(
    src_x: torch.Tensor, dx: torch.Tensor, dy: torch.Tensor, valid: torch.Tensor, iters: int = 4
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Inverts the 2D forward map p -> p + (dx, dy)(p) by fixed-point iteration.

    Starts from the row-wise inverse ``src_x``; a target pixel is a hit when the iteration
    lands on a valid source pixel that maps back to within half a pixel.
    """
    b, t, h, w = dx.shape
    xx = torch.arange(w, dtype=dx.dtype, device=dx.device).expand(b, t, h, w)
    yy = torch.arange(h, dtype=dx.dtype, device=dx.device).view(h, 1).expand(b, t, h, w)
    valid_t = (valid[:, None] if valid.ndim == 3 else valid).to(dx.dtype).expand(b, t, h, w)
    sample = _sampler(torch.stack([dx, dy, valid_t], dim=2))
    sx, sy = src_x, yy - dy
    for _ in range(iters):
        d = sample(sx, sy, 2)  # the displacement only; validity once, at the end
        sx, sy = xx - d[:, :, 0], yy - d[:, :, 1]
    d = sample(sx, sy)
    residual = (sx + d[:, :, 0] - xx).abs() + (sy + d[:, :, 1] - yy).abs()
    inside = (sx >= 0) & (sx <= w - 1) & (sy >= 0) & (sy <= h - 1)
    return sx, sy, (d[:, :, 2] > 0.999) & inside & (residual < 0.5)


class NovelViewWarp(torch.nn.Module):
    """Synthesizes the views I_θ of an object from one or two seed views (Sec. 3).

    The seed views are at angles 0 and ``alpha`` (degrees); a novel view at ``theta`` is
    Eq. 2 with Eq. 7's coefficients, ``x3 - c = a (x1 - c) + b (x2 - c)``, where ``c`` is
    the column of the rotation axis. The forward map of each seed view is inverted
    (:func:`~torch_eigview.geometry.row_maps.invert_row_map`) and the seed images are sampled with kornia's ``remap``
    (bilinear: the tent weights of Eq. 4). With two seed views both are warped and
    blended: where both see a target pixel the nearer view in angle weighs more, where
    only one does (an occlusion in the other) that one is used alone.

    Args:
        alpha: angle of the second seed view in degrees.
        center: column ``c`` of the rotation axis; default ``(W - 1) / 2``.
        max_stretch: a forward-map segment longer than this (pixels) is a depth jump,
            not a surface: it is left to the other view.
        depth_sign: +1 or -1 picks which way depth points towards the camera; ``"auto"``
            decides per object from the correspondences (the visible surface lies in
            front of the rotation axis on average).
        elevation: tilt of the camera's axis out of the plane perpendicular to the
            rotation axis, in degrees (0: the paper's orthographic camera, rows stay rows).
            With a tilt, points also move vertically (``y = K - sin(elevation) (Z cos(phi)
            - X sin(phi))``) and the maps become 2D; :func:`estimate_elevation` measures
            it from a 2D flow (COIL's camera looks down on the turntable).
        blend: how two seed views that both see a target pixel share it: ``"linear"``
            (the default: weights 1 − θ/α and θ/α, a cross-dissolve) or ``"nearest"``
            (the seed nearer in angle alone, seed 1 up to α/2: Eq. 3's form, one image
            sampled per pixel; sharper, as nothing is averaged across the two warps).
            Where only one seed sees a pixel it is used alone either way.
        camera: optional affine camera of the first seed view, (2, 3), (2, 4) ``[M | t]``
            or (3, 4) (Sec. 4's affine camera): a and b are then solved from it by
            :func:`~torch_eigview.geometry.pose.affine_coefficients` (which refuses a camera
            for which Eq. 2 cannot hold) and ``center`` defaults to its axis column
            ``t[0]``. None: the orthographic camera, Eq. 7.

    Example:
        >>> warp = NovelViewWarp(alpha=5.0)
        >>> view1 = torch.rand(1, 1, 8, 8); corr = correspondence_from_disparity(torch.zeros(8, 8))
        >>> warp(view1, None, correspondence=corr, thetas=[0.0, 2.5]).shape
        torch.Size([1, 2, 1, 8, 8])
    """

    def __init__(
        self,
        alpha: float,
        center: float | None = None,
        *,
        max_stretch: float = 3.0,
        depth_sign: float | str = "auto",
        elevation: float = 0.0,
        camera: torch.Tensor | None = None,
        blend: str = "linear",
    ) -> None:
        super().__init__()
        self.alpha = check_alpha(alpha)
        if blend not in BLENDS:
            raise ValueError(f"blend must be one of {BLENDS}, got {blend!r}")
        self.blend = blend
        self.center = None if center is None else check_number(center, "center")
        if not math.isfinite(self.center or 0.0):
            raise ValueError(f"center={center} must be a finite column")
        self.max_stretch = check_number(max_stretch, "max_stretch")
        if not self.max_stretch > 0:
            raise ValueError(f"max_stretch={max_stretch} must be positive")
        if isinstance(depth_sign, bool) or depth_sign not in ("auto", 1, -1, 1.0, -1.0):
            kind = TypeError if isinstance(depth_sign, bool) else ValueError
            raise kind(f"depth_sign must be 'auto', 1 or -1, got {depth_sign!r}")
        self.depth_sign = depth_sign
        self.elevation = check_number(elevation, "elevation")
        if not (math.isfinite(self.elevation) and abs(self.elevation) < 90):
            raise ValueError(f"elevation={elevation} must be an angle in degrees in (-90, 90)")
        self.camera: torch.Tensor | None = None
        if camera is not None:
            # Validates the camera now, at an angle where Eq. 2 is a real constraint.
            affine_coefficients(camera, self.alpha, [self.alpha / 2, -self.alpha])
            if self.elevation != 0.0:
                raise ValueError(
                    f"elevation={elevation} must be 0 with an affine camera (its rows stay rows)"
                )
            self.camera = camera.detach().to("cpu", torch.float64).clone()

    def extra_repr(self) -> str:
        return (
            f"alpha={self.alpha}, center={self.center}, elevation={self.elevation}, "
            f"max_stretch={self.max_stretch}, blend={self.blend!r}"
            + ("" if self.camera is None else ", camera=affine")
        )

    def maps(self, correspondence: Correspondence, thetas: object, n_sources: int = 2) -> WarpMaps:
        """Target→source maps and blend weights for the novel angles ``thetas``.

        Args:
            correspondence: (B, H, W) correspondences between the seed views.
            thetas: (T,) novel angles in degrees from the first seed view.
            n_sources: 2 to blend both seed views, 1 to warp view 1 alone.

        Returns:
            :class:`WarpMaps` with S = ``n_sources``; ``src_y`` is None unless the camera
            has an elevation.
        """
        if n_sources not in (1, 2):
            raise ValueError(f"n_sources must be 1 or 2, got {n_sources}")
        d12 = correspondence.disparity_12
        dtype, device = d12.dtype, d12.device
        theta = as_angle_tensor(thetas, "thetas")
        if bool((theta.abs() >= 90).any()):
            raise ValueError(
                f"thetas must lie within (-90, 90) degrees of the first seed view, got {theta.tolist()}: "
                "beyond that the seed views show the object's other side"
            )
        _, _, w = correspondence.shape
        c = (w - 1) / 2 if self.center is None else self.center
        if self.camera is None:
            coefficients = orthographic_coefficients(theta, self.alpha)
        else:
            affine = affine_coefficients(self.camera, self.alpha, theta)
            coefficients = (affine.a, affine.b)
            c = affine.center if self.center is None else c
        a, b = (v.to(dtype=dtype, device=device).view(1, -1, 1, 1) for v in coefficients)
        th = torch.deg2rad(theta).to(dtype=dtype, device=device).view(1, -1, 1, 1)
        cols = torch.arange(w, dtype=dtype, device=device).expand_as(d12)
        sign = self._depth_sign(cols - c, cols + d12 - c, correspondence.valid_12)
        geo = _Geometry(a, b, th, c, math.radians(self.alpha), sign, self.max_stretch, self._tilt)
        # Source view 1: x1 is the pixel grid, x2 its match. Source view 2: the other way.
        src1, srcy1, hit1 = geo.source_maps(cols, cols + d12, correspondence.valid_12, second=False)
        if n_sources == 1:
            sy = None if srcy1 is None else srcy1[None]
            return WarpMaps(src1[None], torch.ones_like(src1)[None], hit1[None], theta, sy)
        src2, srcy2, hit2 = geo.source_maps(
            cols + correspondence.disparity_21, cols, correspondence.valid_21, second=True
        )
        # Where both views see a pixel the nearer one in angle weighs more; where one is
        # occluded the other is used alone; where neither sees it, the angular weights.
        lam2 = self._share_of_second(th)
        both, neither = hit1 & hit2, ~hit1 & ~hit2
        w1 = torch.where(both | neither, (1 - lam2).expand_as(src1), hit1.to(dtype))
        src_y = None if srcy1 is None or srcy2 is None else torch.stack([srcy1, srcy2])
        return WarpMaps(
            torch.stack([src1, src2]), torch.stack([w1, 1 - w1]), torch.stack([hit1, hit2]), theta, src_y
        )

    def _share_of_second(self, theta_rad: torch.Tensor) -> torch.Tensor:
        """The second seed's weight where both seeds see a pixel (``blend``), per angle."""
        lam2 = (theta_rad / math.radians(self.alpha)).clamp(0, 1)
        return lam2 if self.blend == "linear" else (lam2 > 0.5).to(lam2.dtype)

    @property
    def _tilt(self) -> float:
        return math.sin(math.radians(self.elevation))

    def _depth_sign(self, xa: torch.Tensor, xb: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """(B, 1, 1, 1) sign that makes depth point towards the camera."""
        if self.depth_sign != "auto":
            return torch.full(
                (xa.shape[0], 1, 1, 1), float(self.depth_sign), dtype=xa.dtype, device=xa.device
            )
        al = math.radians(self.alpha)
        z = (xb - xa * math.cos(al)) / math.sin(al)
        mean_z = (z * valid).sum(dim=(-1, -2)) / valid.sum(dim=(-1, -2)).clamp_min(1)
        return torch.where(mean_z >= 0, 1.0, -1.0).to(xa.dtype).view(-1, 1, 1, 1)

    @staticmethod
    def apply_maps(maps: WarpMaps, views: torch.Tensor, masks: torch.Tensor | None = None) -> torch.Tensor:
        """Samples and blends the seed views with precomputed maps.

        Args:
            maps: :class:`WarpMaps` with S sources for B objects and T angles.
            views: (S, B, C, H, W) seed images.
            masks: optional (S, B, H, W) foreground masks of the seed views (non-zero is
                foreground, any dtype):
                *silhouette-aware* sampling. Each target pixel's bilinear taps, over both
                seeds and with the blend weights, then count foreground source pixels
                only and are renormalized to sum to 1; a target pixel whose foreground
                share is below 1/2 is background (0). Without it a pixel on the
                silhouette mixes object and background (a dark rim); with it the result
                is still linear in ``views`` for fixed masks (the weights of
                :meth:`SparseViewOperator.from_maps` with ``masks``; the two round the
                foreground share differently, so a pixel within float rounding of 1/2
                can fall on different sides of it).

        Returns:
            (B, T, C, H, W) synthesized views.
        """
        s, b, t, h, w = maps.src_x.shape
        c = views.shape[2]
        if masks is not None:
            if masks.shape != (s, b, h, w):
                raise ValueError(
                    f"masks must have shape (S, B, H, W) = {(s, b, h, w)}, got {tuple(masks.shape)}"
                )
            m = (masks.to(views.device) != 0).to(views.dtype)[:, :, None]
            views = torch.cat([views * m, m], dim=2)  # the mask rides along: one warp for both
        rows = torch.arange(h, dtype=views.dtype, device=views.device).view(1, h, 1).expand(b * t, h, w)
        ch = views.shape[2]
        out = views.new_zeros(b, t, ch, h, w)
        for i in range(s):
            img = views[i][:, None].expand(b, t, ch, h, w).reshape(b * t, ch, h, w)
            map_x = maps.src_x[i].reshape(b * t, h, w).to(views.dtype)
            map_y = rows if maps.src_y is None else maps.src_y[i].reshape(b * t, h, w).to(views.dtype)
            warped = remap(img, map_x, map_y, mode="bilinear", padding_mode="zeros", align_corners=True)
            out = out + maps.weight[i].to(views.dtype)[:, :, None] * warped.view(b, t, ch, h, w)
        if masks is None:
            return out
        return _renormalize(out[:, :, :c], out[:, :, c:])

    def forward(
        self,
        view1: torch.Tensor,
        view2: torch.Tensor | None = None,
        *,
        correspondence: Correspondence,
        thetas: object,
        masks: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Synthesizes the novel views.

        Args:
            view1: (B, C, H, W) or (C, H, W) first seed view (angle 0).
            view2: same shape, second seed view (angle ``alpha``), or None to warp view 1 alone.
            correspondence: (B, H, W) correspondences between the seed views.
            thetas: (T,) novel angles in degrees.
            masks: optional foreground masks of the seed views, (S, B, H, W) (or (S, H, W)
                unbatched; S = 1 or 2 as views are given): silhouette-aware sampling, see
                :meth:`apply_maps`.

        Returns:
            (B, T, C, H, W) views (or (T, C, H, W) for unbatched input); differentiable
            with respect to ``view1`` and ``view2``.
        """
        v1 = check_float_tensor(view1, "view1")
        check_ndim(v1, "view1", (3, 4), "(B, C, H, W) or (C, H, W)")
        unbatched = v1.ndim == 3
        views = [v1[None] if unbatched else v1]
        if view2 is not None:
            v2 = check_float_tensor(view2, "view2")
            if v2.shape != v1.shape:
                raise ValueError(
                    f"view2 must have the shape of view1 {tuple(v1.shape)}, got {tuple(v2.shape)}"
                )
            if v2.dtype != v1.dtype:
                raise TypeError(f"view2 must have the dtype of view1 ({v1.dtype}), got {v2.dtype}")
            views.append(v2[None] if unbatched else v2)
        b, _, h, w = views[0].shape
        if correspondence.shape != (b, h, w):
            raise ValueError(
                f"correspondence must have shape (B, H, W) = {(b, h, w)} to match the views, "
                f"got {correspondence.shape}"
            )
        if masks is not None:
            if not isinstance(masks, torch.Tensor):
                raise TypeError(f"masks must be a tensor, got {type(masks).__name__}")
            expected = (len(views), h, w) if unbatched else (len(views), b, h, w)
            if masks.shape != expected:
                raise ValueError(f"masks must have shape {expected} (S, [B,] H, W), got {tuple(masks.shape)}")
            masks = (masks[:, None] if unbatched else masks).to(v1.device)
        corr = correspondence.to(device=v1.device)
        maps = self.maps(corr, thetas, n_sources=len(views))
        out = self.apply_maps(maps, torch.stack(views), masks)
        return out[0] if unbatched else out
