"""Novel views for the perspective camera (Sec. 4): trifocal transfer and a 2D warp.

Convention:
    The turntable of the paper with a pinhole camera: the object turns by φ about its
    vertical axis Y and the camera, at ``distance`` from the axis on the zc axis, looks at
    it; a point P is at ``X_cam = S·R_y(φ)·P + (0, 0, distance)`` with
    ``S = diag(1, −1, −1)`` (x right, y down, z forward) and is imaged at ``K·X_cam``
    (:class:`~torch_eigview.datasets.cameras.PerspectiveCamera` renders exactly this). Images
    are (C, H, W), x the column, y the row, pixel centres at integers.

Every point moves in both coordinates, so each seed pixel's position in the novel view
at θ is transferred with the trifocal tensor ``<seed, other seed, θ>``
(:func:`~torch_eigview.geometry.trifocal.novel_view_tensor_from_cameras`: the seed pair's tensor
and the novel view's rotation and translation, Shashua and Avidan's tensor operator) and
its match in the other seed view; the forward map is inverted by triangle rasterization
with a z-buffer (:func:`~torch_eigview.warp.raster.invert_map_2d`; depths from the seed pair
by triangulation, kornia), and the seed images are sampled with 2D bilinear weights by
``grid_sample``, as kornia's ``remap`` samples them (:class:`~torch_eigview.warp.base.ViewWarp`). :class:`~torch_eigview.warp.operator.SparseViewOperator` builds the same
views as G·C with whole-image coefficient vectors (``layout="image"``).
"""

from __future__ import annotations

import math

import torch
from kornia.geometry.epipolar import triangulate_points

from torch_eigview.check import check_int, check_number
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.pose import rotation_y
from torch_eigview.geometry.transfer import transfer_points
from torch_eigview.geometry.trifocal import novel_view_tensor_from_cameras
from torch_eigview.warp.base import ViewWarp
from torch_eigview.warp.maps import WarpMaps
from torch_eigview.warp.raster import invert_map_2d

__all__ = ["PerspectiveWarp", "turntable_pose"]

_FLIP = torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=torch.float64))
_OUTSIDE = -2.0  # a source position outside every image: zeros padding samples 0


def turntable_pose(theta: float, distance: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Rotation (3, 3) and translation (3,) of the camera seeing the object turned by ``theta``.

    ``X_cam = R·P + t`` with ``R = diag(1, −1, −1)·R_y(theta)`` and ``t = (0, 0, distance)``
    (float64); ``theta`` in degrees.
    """
    r = _FLIP @ rotation_y(torch.tensor(math.radians(theta), dtype=torch.float64))
    return r, torch.tensor([0.0, 0.0, float(distance)], dtype=torch.float64)


def _grow(
    src_x: torch.Tensor, src_y: torch.Tensor, hit: torch.Tensor, steps: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Extends the maps (B, T, H, W) by ``steps`` pixels beyond the hit region.

    A pixel next to hit pixels q takes the mean of ``src(q) − (q − p)`` over them (the
    map continued with a unit Jacobian): the silhouette's last half pixel, whose source
    lies between a foreground and a background seed pixel, and small holes. Returns the
    grown maps and the mask of the pixels they now cover (hits included).
    """
    b, t, h, w = hit.shape
    covered = hit.clone()
    sx = torch.where(hit, src_x, 0.0)
    sy = torch.where(hit, src_y, 0.0)
    for _ in range(steps):
        pad = (1, 1, 1, 1)
        px = torch.nn.functional.pad(sx.view(b * t, 1, h, w), pad).view(b, t, h + 2, w + 2)
        py = torch.nn.functional.pad(sy.view(b * t, 1, h, w), pad).view(b, t, h + 2, w + 2)
        pc = torch.nn.functional.pad(covered.view(b * t, 1, h, w).to(sx.dtype), pad).view(b, t, h + 2, w + 2)
        acc_x, acc_y, count = torch.zeros_like(sx), torch.zeros_like(sy), torch.zeros_like(sx)
        for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            win = (slice(None), slice(None), slice(1 + dy, 1 + dy + h), slice(1 + dx, 1 + dx + w))
            c = pc[win]
            acc_x += c * (px[win] - dx)
            acc_y += c * (py[win] - dy)
            count += c
        new = ~covered & (count > 0)
        sx = torch.where(new, acc_x / count.clamp_min(1), sx)
        sy = torch.where(new, acc_y / count.clamp_min(1), sy)
        covered = covered | new
    return sx, sy, covered


def _check_intrinsics(k: object) -> torch.Tensor:
    if not isinstance(k, torch.Tensor):
        raise TypeError(f"K must be a (3, 3) torch.Tensor of intrinsics, got {type(k).__name__}")
    if not k.is_floating_point():
        raise TypeError(f"K must have a floating dtype, got {k.dtype}")
    if k.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {tuple(k.shape)}")
    k64 = k.detach().to("cpu", torch.float64)
    if not bool(torch.isfinite(k64).all()):
        raise ValueError("K must be finite, got NaN or infinite entries")
    if abs(float(torch.linalg.det(k64))) <= 1e-12 * float(k64.abs().max()) ** 3:
        raise ValueError(f"K must be invertible (a singular camera), got {k64.tolist()}")
    return k64


class PerspectiveWarp(ViewWarp):
    """Synthesizes the views I_θ of an object from two seed views of a perspective camera.

    The seed views are the camera (intrinsics ``K``, at ``distance`` from the rotation
    axis) with the object turned by 0 and ``alpha`` degrees; a novel view at θ is
    rendered by trifocal point transfer (see the module docstring), both seed views
    warped and blended as in :class:`~torch_eigview.warp.novel_view.NovelViewWarp`: where both see
    a target pixel the nearer one in angle weighs more, where one is occluded the other
    is used alone, and a target pixel that neither seed view sees stays 0 (background).

    Args:
        alpha: angle of the second seed view in degrees.
        K: (3, 3) intrinsics of the camera.
        distance: distance from the camera centre to the rotation axis (the unit of the
            scene; only the ratio to the object's size matters).
        max_stretch: a forward-mapped triangle edge longer than this (pixels) is a depth
            jump, not a surface.
        line: the line through the match in the other seed view used for the transfer
            (:func:`~torch_eigview.geometry.transfer.transfer_points`).
        grow: pixels by which each seed's map is continued beyond what it hits, for the
            target pixels that neither seed hits (the silhouette's last half pixel,
            whose source lies between a foreground and a background seed pixel).
        blend: ``"linear"`` or ``"nearest"``, as :class:`~torch_eigview.warp.novel_view.NovelViewWarp`'s.

    The correspondences must be 2D: ``vertical_12`` and ``vertical_21`` set (as
    :func:`~torch_eigview.geometry.flow.estimate_correspondence` returns, or
    :func:`~torch_eigview.datasets.correspondence.exact_correspondence_2d`).
    """

    K: torch.Tensor

    def __init__(
        self,
        alpha: float,
        K: torch.Tensor,
        distance: float,
        *,
        max_stretch: float = 3.0,
        line: str = "perpendicular",
        grow: int = 2,
        blend: str = "linear",
    ) -> None:
        super().__init__(alpha, max_stretch=max_stretch, blend=blend)
        # A CPU float64 constant, not a buffer: the camera geometry is built in float64 on the
        # CPU and moved to the correspondences' device, whatever .to() did to the module.
        self.K = _check_intrinsics(K)
        dist = check_number(distance, "distance")
        if not (math.isfinite(dist) and dist > 0):
            raise ValueError(f"distance={distance} must be a positive finite number")
        self.distance = dist
        if line not in ("perpendicular", "vertical", "paper"):
            raise ValueError(f"line must be 'perpendicular', 'vertical' or 'paper', got {line!r}")
        self.line = line
        self.grow = check_int(grow, "grow", minimum=0)

    def extra_repr(self) -> str:
        return (
            f"alpha={self.alpha}, distance={self.distance}, max_stretch={self.max_stretch}, "
            f"line={self.line!r}, blend={self.blend!r}"
        )

    def _source(
        self,
        theta: torch.Tensor,
        shift_x: torch.Tensor,
        shift_y: torch.Tensor,
        valid: torch.Tensor,
        angles: tuple[float, float],
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Maps (B, T, H, W) with seed view ``angles[0]`` as the source, matched in ``angles[1]``:
        ``(src_x, src_y, hit, covered)``, ``covered`` = hit or reached by :func:`_grow`."""
        b, h, w = shift_x.shape
        dtype, device = shift_x.dtype, shift_x.device
        f64 = torch.float64  # the geometry in float64, on the correspondences' device
        k = self.K.to(torch.float64)
        yy, xx = torch.meshgrid(
            torch.arange(h, dtype=f64, device=device),
            torch.arange(w, dtype=f64, device=device),
            indexing="ij",
        )
        pa = torch.stack([xx.expand(b, h, w), yy.expand(b, h, w)], dim=-1).reshape(b, h * w, 2)
        pb = pa + torch.stack([shift_x, shift_y], dim=-1).to(f64).reshape(b, h * w, 2)
        ra, ta = turntable_pose(angles[0], self.distance)
        rb, tb = turntable_pose(angles[1], self.distance)
        proj_a = (k @ torch.cat([ra, ta[:, None]], dim=1)).to(device)
        proj_b = (k @ torch.cat([rb, tb[:, None]], dim=1)).to(device)
        points = triangulate_points(proj_a.expand(b, 3, 4), proj_b.expand(b, 3, 4), pa, pb, solver="svd")
        dst, depth, own = [], [], []
        for th in theta.tolist():
            rn, tn = turntable_pose(th, self.distance)
            if th == angles[0]:  # the source view itself: no correspondence needed
                dst.append(pa)
                own.append(True)
            else:
                r_rel = rn @ rb.T
                tensor = novel_view_tensor_from_cameras(k, ra, ta, rb, tb, r_rel, tn - r_rel @ tb)
                dst.append(transfer_points(tensor.to(device), pa, pb, line=self.line))
                own.append(False)
            rn, tn = rn.to(device), tn.to(device)
            depth.append(-(points @ rn[2] + tn[2]))  # larger = nearer the novel camera
        t = len(dst)
        dst_xy = torch.stack(dst, dim=1).reshape(b, t, h, w, 2)
        key = torch.stack(depth, dim=1).reshape(b, t, h, w)
        ok = torch.isfinite(dst_xy).all(-1) & torch.isfinite(key)
        own_view = torch.tensor(own, device=device).view(1, t, 1, 1)
        use = (valid.to(device)[:, None] | own_view) & ok
        dst_xy = torch.where(ok[..., None], dst_xy, 0.0)
        key = torch.where(ok, key, 0.0)
        src_x, src_y, hit = invert_map_2d(
            dst_xy[..., 0].to(dtype), dst_xy[..., 1].to(dtype), use, key.to(dtype), self.max_stretch
        )
        src_x, src_y, grown = _grow(src_x, src_y, hit, self.grow)
        return src_x, src_y, hit, grown

    def maps(self, correspondence: Correspondence, thetas: object, n_sources: int = 2) -> WarpMaps:
        """Target→source maps (``src_y`` set) and blend weights for the novel angles ``thetas``.

        Args:
            correspondence: (B, H, W) 2D correspondences between the seed views.
            thetas: (T,) novel angles in degrees from the first seed view, in (−90, 90).
            n_sources: 2 to blend both seed views, 1 to warp view 1 alone.

        Returns:
            :class:`~torch_eigview.warp.maps.WarpMaps` with S = ``n_sources``.
        """
        self._check_n_sources(n_sources)
        if correspondence.vertical_12 is None or (n_sources == 2 and correspondence.vertical_21 is None):
            raise ValueError(
                "correspondence must be 2D for a perspective camera (vertical_12 and vertical_21 set, "
                "as estimate_correspondence returns), got a horizontal-only one"
            )
        theta = self._novel_angles(thetas)
        dtype = correspondence.disparity_12.dtype
        src1, srcy1, hit1, cov1 = self._source(
            theta,
            correspondence.disparity_12,
            correspondence.vertical_12,
            correspondence.valid_12,
            (0.0, self.alpha),
        )
        if n_sources == 1:
            src1 = torch.where(cov1, src1, _OUTSIDE)
            srcy1 = torch.where(cov1, srcy1, _OUTSIDE)
            return WarpMaps(src1[None], cov1.to(dtype)[None], hit1[None], theta, srcy1[None])
        assert correspondence.vertical_21 is not None
        src2, srcy2, hit2, cov2 = self._source(
            theta,
            correspondence.disparity_21,
            correspondence.vertical_21,
            correspondence.valid_21,
            (self.alpha, 0.0),
        )
        lam2 = self._share_of_second(torch.deg2rad(theta)).to(dtype=dtype, device=src1.device)
        lam2 = lam2.view(1, -1, 1, 1).expand_as(src1)

        def blend(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            # Both: the nearer seed in angle weighs more; one: it alone.
            return torch.where(a & b, 1 - lam2, a.to(dtype)), torch.where(a & b, lam2, b.to(dtype))

        # The seeds' hits first; where neither hits, their grown maps the same way.
        (h1, h2), (c1, c2) = blend(hit1, hit2), blend(cov1, cov2)
        any_hit = hit1 | hit2
        weight = torch.stack([torch.where(any_hit, h1, c1), torch.where(any_hit, h2, c2)])
        src_x = torch.stack([torch.where(cov1, src1, _OUTSIDE), torch.where(cov2, src2, _OUTSIDE)])
        src_y = torch.stack([torch.where(cov1, srcy1, _OUTSIDE), torch.where(cov2, srcy2, _OUTSIDE)])
        return WarpMaps(src_x, weight, torch.stack([hit1, hit2]), theta, src_y)
