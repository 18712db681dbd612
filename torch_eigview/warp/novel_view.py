"""Novel-view synthesis for the orthographic and the affine camera (Sec. 3, Eqs. 2 and 7).

Convention:
    Images are (C, H, W) (batched (B, C, H, W)); x is the column, y the row; pixel
    centres are at integer coordinates. The camera rotates about the vertical axis, so
    pixels move along their rows (Eq. 2): the maps are target → source columns in pixels
    (:class:`~torch_eigview.warp.maps.RowGeometry`), 2D only for a tilted camera.

The synthesized view is linear in the seed images: bilinear (tent, Eq. 4) sampling with
weights that depend only on the correspondences, blended over the two seed views with
weights that also depend only on the correspondences. :mod:`torch_eigview.warp.operator`
builds the same linear map as the sparse product G·C of Eqs. 3–6.
"""

from __future__ import annotations

import math

import torch

from torch_eigview.check import check_number
from torch_eigview.geometry.correspondence import Correspondence, check_correspondence
from torch_eigview.geometry.pose import affine_coefficients, orthographic_coefficients
from torch_eigview.warp.base import ViewWarp
from torch_eigview.warp.maps import RowGeometry, WarpMaps

__all__ = ["NovelViewWarp"]


class NovelViewWarp(ViewWarp):
    """Synthesizes the views I_θ of an object from one or two seed views (Sec. 3).

    The seed views are at angles 0 and ``alpha`` (degrees); a novel view at ``theta`` is
    Eq. 2 with Eq. 7's coefficients, ``x3 - c = a (x1 - c) + b (x2 - c)``, where ``c`` is
    the column of the rotation axis. The forward map of each seed view is inverted
    (:func:`~torch_eigview.geometry.row_maps.invert_row_map`) and the seed images are
    sampled bilinearly (the tent weights of Eq. 4) by ``grid_sample``, as kornia's
    ``remap`` samples them, bit for bit (:class:`~torch_eigview.warp.base.ViewWarp`). With
    two seed views both are warped and blended: where both see a target pixel the nearer
    view in angle weighs more, where only one does (an occlusion in the other) that one is
    used alone.

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
        >>> from torch_eigview.geometry import correspondence_from_disparity
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
        super().__init__(alpha, max_stretch=max_stretch, blend=blend)
        self.center = None if center is None else check_number(center, "center")
        if not math.isfinite(self.center or 0.0):
            raise ValueError(f"center={center} must be a finite column")
        if isinstance(depth_sign, bool) or depth_sign not in ("auto", 1, -1, 1.0, -1.0):
            kind = TypeError if isinstance(depth_sign, bool) else ValueError
            raise kind(f"depth_sign must be 'auto', 1 or -1, got {depth_sign!r}")
        self.depth_sign = depth_sign
        self.elevation = check_number(elevation, "elevation")
        if not (math.isfinite(self.elevation) and abs(self.elevation) < 90):
            raise ValueError(f"elevation={elevation} must be an angle in degrees in (-90, 90)")
        self.camera: torch.Tensor | None = None
        if camera is not None:
            # Validates the camera at construction, at an angle where Eq. 2 is a real constraint.
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

    def maps(
        self,
        correspondence: Correspondence,
        thetas: object,
        n_sources: int = 2,
        *,
        support: torch.Tensor | None = None,
    ) -> WarpMaps:
        """Eq. 2's target→source maps and blend weights for the novel angles ``thetas``.

        Args:
            correspondence: (B, H, W) correspondences between the seed views (the
                horizontal disparities; a tilted camera's vertical motion follows from them).
            thetas: (T,) novel angles in degrees from the first seed view, within a quarter
                turn of it, the same for every object; or a (B, T) tensor, each object's own
                angles (B different objects at B different angles: ``(B, 1)``). Every pixel's
                map depends on its own object's angle only, so the (B, T) maps equal the
                per-object calls stacked, built in one batched pass.
            n_sources: 2 to blend both seed views, 1 to warp view 1 alone.
            support: optional (B, H) bool, the rows of the seed views that hold a pixel
                other than zero (either seed, any channel). Given, the maps hold only the
                target rows that can sample such a row (the object's rows and the few its
                tilt reaches; ``WarpMaps.row0`` the first), each as in the whole-grid maps:
                every other synthesized row is zero, and :meth:`apply_maps` writes it so.
                The band's bounds are a few scalars read on the host (a sync on a GPU).

        Returns:
            :class:`~torch_eigview.warp.maps.WarpMaps` with S = ``n_sources`` and ``thetas``
            as given ((T,) or (B, T)); ``src_y`` is None unless the camera has an elevation.
        """
        self._check_n_sources(n_sources)
        d12 = check_correspondence(correspondence).disparity_12
        if support is not None:
            if not isinstance(support, torch.Tensor) or support.dtype != torch.bool:
                raise TypeError(
                    f"support must be a bool tensor, got {getattr(support, 'dtype', type(support).__name__)}"
                )
            if support.shape != correspondence.shape[:2]:
                raise ValueError(
                    f"support must have shape (B, H) = {correspondence.shape[:2]}, got {tuple(support.shape)}"
                )
            support = support.to(d12.device)
        dtype, device = d12.dtype, d12.device
        b_objects, _, w = correspondence.shape
        theta = self._novel_angles(thetas, batch=b_objects)
        c = (w - 1) / 2 if self.center is None else self.center
        a, b, c = self._coefficients(theta, c)
        # (1, T, 1, 1) for shared angles, (B, T, 1, 1) per object: both broadcast against
        # the (B, 1, H, W) pixel grids of RowGeometry.
        shape = (1 if theta.ndim == 1 else b_objects, theta.shape[-1], 1, 1)
        a, b = (v.to(dtype=dtype, device=device).view(shape) for v in (a, b))
        th = torch.deg2rad(theta).to(dtype=dtype, device=device).view(shape)
        cols = torch.arange(w, dtype=dtype, device=device)
        # x - c of view 1 as a (W,) row, broadcast by the arithmetic rather than expanded.
        sign = self._depth_sign(cols - c, cols + d12 - c, correspondence.valid_12)
        geo = RowGeometry(a, b, th, c, math.radians(self.alpha), sign, self.max_stretch, self._tilt)
        return geo.maps(correspondence, theta, self._share_of_second(th), n_sources, support)

    def _coefficients(self, theta: torch.Tensor, c: float) -> tuple[torch.Tensor, torch.Tensor, float]:
        """Eq. 2's (a, b), each of the shape of ``theta`` ((T,) or (B, T)), and the axis column."""
        flat = theta.reshape(-1)
        if flat.numel() == 0:  # an empty batch of per-object angles: nothing to solve
            return flat, flat, c
        if self.camera is None:
            a, b = orthographic_coefficients(flat, self.alpha)
        else:
            affine = affine_coefficients(self.camera, self.alpha, flat)
            a, b = affine.a, affine.b
            c = affine.center if self.center is None else c
        return a.view(theta.shape), b.view(theta.shape), c

    @property
    def _tilt(self) -> float:
        return math.sin(math.radians(self.elevation))

    def _depth_sign(self, xa: torch.Tensor, xb: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """(B, 1, 1, 1) sign that makes depth point towards the camera; ``xb`` and ``valid``
        are (B, H, W), ``xa`` broadcasts to them."""
        if self.depth_sign != "auto":
            return torch.full(
                (xb.shape[0], 1, 1, 1), float(self.depth_sign), dtype=xb.dtype, device=xb.device
            )
        al = math.radians(self.alpha)
        z = (xb - xa * math.cos(al)) / math.sin(al)
        mean_z = (z * valid).sum(dim=(-1, -2)) / valid.count_nonzero(dim=(-1, -2)).clamp_min(1)
        return torch.where(mean_z >= 0, 1.0, -1.0).to(xb.dtype).view(-1, 1, 1, 1)
