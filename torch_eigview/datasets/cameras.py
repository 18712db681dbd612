"""The cameras of the synthetic renderer: affine (orthographic as a special case) and pinhole.

Convention:
    An object turned by θ (degrees) about its vertical axis Y is seen in the camera frame
    at ``xc = X cos θ + Z sin θ``, ``yc = Y``, ``zc = Z cos θ − X sin θ``; the camera looks
    along −zc (nearer points have larger zc). Images are (C, H, W) with x the column and
    y the row, pixel centres at integers. The orthographic camera images
    ``x = cx + s·xc``, ``y = cy − s·yc`` with ``cx = (W − 1)/2``, ``cy = (H − 1)/2``: the
    rotation axis is the centre column, as :class:`~torch_eigview.warp.novel_view.NovelViewWarp`
    assumes, and x obeys Eq. 2 exactly. Depths are distances along the viewing direction
    (smaller is nearer).

A camera gives the ray of each pixel position (parallel rays for the affine cameras, rays
through the pinhole for the perspective one) and projects camera-frame points to pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from torch_eigview.check import check_choice, check_number

__all__ = [
    "CAMERAS",
    "GEOMETRY_DTYPE",
    "AffineCamera",
    "Camera",
    "OrthographicCamera",
    "PerspectiveCamera",
    "check_camera",
    "make_camera",
]

GEOMETRY_DTYPE = torch.float64  # geometry is computed in float64: bisection to ~1e-7 object units


def _check_size(size: object) -> tuple[int, int]:
    hw = (size, size) if isinstance(size, int) and not isinstance(size, bool) else size
    if (
        not isinstance(hw, tuple)
        or len(hw) != 2
        or any(isinstance(v, bool) or not isinstance(v, int) for v in hw)
    ):
        raise TypeError(f"size must be an int or a tuple (H, W) of ints, got {size!r}")
    if hw[0] < 1 or hw[1] < 1:
        raise ValueError(f"size={size!r} must be positive (image height and width in pixels)")
    return hw[0], hw[1]


class Camera:
    """Interface of the cameras: the rays of pixel positions and the projection of points.

    :func:`~torch_eigview.datasets.renderer.render` accepts any of its subclasses,
    :class:`AffineCamera` (:func:`OrthographicCamera`) and :class:`PerspectiveCamera`.
    """

    height: int
    width: int

    def rays(self, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Origins and unit directions (..., 3) in the camera frame of pixels (x, y) (...,)."""
        raise NotImplementedError

    def project(self, pc: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Pixel (x, y) and depth (...,) of camera-frame points (..., 3)."""
        raise NotImplementedError

    def check_outside(self, radius: float) -> None:
        """Raises ValueError when the camera sits within ``radius`` of the object's centre."""


@dataclass(frozen=True)
class AffineCamera(Camera):
    """Affine camera: ``(x, y) = M @ Pc + offset``, a general scaled orthographic projection.

    Args:
        matrix: (2, 3) M of rank 2, in pixels per object unit; the viewing direction is
            its null space, oriented towards −zc.
        size: image size, an int or (H, W).
        offset: (2,) image position of the object's centre; default the image centre.
    """

    matrix: tuple[tuple[float, float, float], tuple[float, float, float]]
    size: int | tuple[int, int] = 128
    offset: tuple[float, float] | None = None
    _m: torch.Tensor = field(init=False, repr=False, compare=False)
    _pinv: torch.Tensor = field(init=False, repr=False, compare=False)
    _dir: torch.Tensor = field(init=False, repr=False, compare=False)
    _off: torch.Tensor = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        h, w = _check_size(self.size)
        m = torch.as_tensor(self.matrix, dtype=GEOMETRY_DTYPE)
        if m.shape != (2, 3) or not bool(torch.isfinite(m).all()):
            raise ValueError(f"matrix must be a finite (2, 3) affine camera matrix, got {self.matrix!r}")
        d = torch.linalg.cross(m[0], m[1])
        if float(d.norm()) < 1e-9 * float(m.norm()) ** 2:
            raise ValueError(f"matrix={self.matrix!r} must have rank 2 (its rows are parallel)")
        d = d / d.norm()
        d = -d if float(d[2]) > 0 else d  # look towards -zc
        off = ((w - 1) / 2, (h - 1) / 2) if self.offset is None else self.offset
        object.__setattr__(self, "height", h)
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "_m", m)
        object.__setattr__(self, "_pinv", m.T @ torch.linalg.inv(m @ m.T))
        object.__setattr__(self, "_dir", d)
        object.__setattr__(self, "_off", torch.tensor(off, dtype=GEOMETRY_DTYPE))

    def rays(self, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        uv = torch.stack([x, y], dim=-1) - self._off
        origin = uv @ self._pinv.T  # minimum-norm point: origin ⟂ direction
        return origin, self._dir.expand_as(origin)

    @property
    def P(self) -> torch.Tensor:
        """(2, 4) affine camera matrix ``[M | offset]`` (float64) of the view at θ = 0."""
        return torch.cat([self._m, self._off[:, None]], dim=1)

    def project(self, pc: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        uv = pc @ self._m.T + self._off
        return uv[..., 0], uv[..., 1], pc @ self._dir


def OrthographicCamera(size: int | tuple[int, int] = 128, scale: float | None = None) -> AffineCamera:
    """The paper's orthographic camera: ``x = cx + scale·xc``, ``y = cy − scale·yc``.

    Args:
        size: image size, an int or (H, W).
        scale: pixels per object unit; default ``0.45·min(H, W)`` (an object of radius 1
            fills 90% of the shorter side).

    Returns:
        An :class:`AffineCamera` with ``M = [[s, 0, 0], [0, −s, 0]]``.
    """
    h, w = _check_size(size)
    s = 0.45 * min(h, w) if scale is None else check_number(scale, "scale")
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"scale={scale} must be a positive number of pixels per object unit")
    return AffineCamera(((s, 0.0, 0.0), (0.0, -s, 0.0)), (h, w))


@dataclass(frozen=True)
class PerspectiveCamera(Camera):
    """Pinhole camera on the zc axis at ``distance`` from the rotation axis, looking at it.

    A camera-frame point ``Pc`` has camera coordinates ``(xc, −yc, distance − zc)`` (x
    right, y down, z forward, the depth), imaged at ``K @ (xc, −yc, distance − zc)``.

    Args:
        size: image size, an int or (H, W).
        distance: distance from the camera centre to the rotation axis, object units.
        K: (3, 3) intrinsics; default focal ``0.45·min(H, W)·distance`` (an object of
            radius 1 at the axis fills about 90% of the shorter side) and the principal
            point at the image centre.
    """

    size: int | tuple[int, int] = 128
    distance: float = 4.0
    K: tuple[tuple[float, ...], ...] | None = None
    _k: torch.Tensor = field(init=False, repr=False, compare=False)
    _kinv: torch.Tensor = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        h, w = _check_size(self.size)
        dist = check_number(self.distance, "distance")
        if not (math.isfinite(dist) and dist > 0):
            raise ValueError(f"distance={self.distance} must be a positive number of object units")
        if self.K is None:
            f = 0.45 * min(h, w) * dist
            k = torch.tensor([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]], dtype=GEOMETRY_DTYPE)
        else:
            k = torch.as_tensor(self.K, dtype=GEOMETRY_DTYPE)
            if k.shape != (3, 3) or not bool(torch.isfinite(k).all()) or abs(float(torch.det(k))) < 1e-12:
                raise ValueError(f"K must be a finite invertible (3, 3) intrinsics matrix, got {self.K!r}")
        object.__setattr__(self, "height", h)
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "_k", k)
        object.__setattr__(self, "_kinv", torch.linalg.inv(k))

    def check_outside(self, radius: float) -> None:
        if self.distance <= radius:
            raise ValueError(
                f"distance={self.distance} must exceed the object's radius {radius}: "
                "the perspective camera would be inside the object"
            )

    def rays(self, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        pix = torch.stack([x, y, torch.ones_like(x)], dim=-1)
        cam = pix @ self._kinv.T
        d = torch.stack([cam[..., 0], -cam[..., 1], -cam[..., 2]], dim=-1)
        d = d / d.norm(dim=-1, keepdim=True)
        origin = torch.tensor([0.0, 0.0, self.distance], dtype=GEOMETRY_DTYPE).expand_as(d)
        return origin, d

    def project(self, pc: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        cam = torch.stack([pc[..., 0], -pc[..., 1], self.distance - pc[..., 2]], dim=-1)
        q = cam @ self._k.T
        return q[..., 0] / q[..., 2], q[..., 1] / q[..., 2], cam[..., 2]


CAMERAS: tuple[str, ...] = ("orthographic", "affine", "perspective")


def make_camera(name: str, **kwargs: object) -> AffineCamera | PerspectiveCamera:
    """A camera by name: ``"orthographic"``, ``"affine"`` or ``"perspective"``, with its arguments.

    Raises:
        TypeError: ``name`` is not a str.
        ValueError: ``name`` is not one of :data:`CAMERAS`.
    """
    name = check_choice(name, "name", CAMERAS)
    if name == "orthographic":
        return OrthographicCamera(**kwargs)  # type: ignore[arg-type]
    if name == "affine":
        return AffineCamera(**kwargs)  # type: ignore[arg-type]
    return PerspectiveCamera(**kwargs)  # type: ignore[arg-type]


def check_camera(camera: object) -> Camera:
    """``camera`` as a :class:`Camera`; TypeError when it is none."""
    if not isinstance(camera, Camera):
        raise TypeError(f"camera must be an AffineCamera or a PerspectiveCamera, got {type(camera).__name__}")
    return camera
