"""A small ray-casting renderer for the synthetic objects.

Every pixel casts one ray of its camera (:mod:`torch_eigview.datasets.cameras`, whose
docstring gives the conventions); the first surface crossing is bracketed by sampling
``f`` along the ray inside the object's bounding sphere and refined by bisection. Depths
are +inf on the background.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from torch_eigview.check import check_number
from torch_eigview.datasets.backdrop import Backdrop
from torch_eigview.datasets.cameras import GEOMETRY_DTYPE, Camera, check_camera
from torch_eigview.datasets.shapes import SyntheticObject
from torch_eigview.geometry.pose import rotation_y

__all__ = [
    "Render",
    "check_object",
    "pixel_grid",
    "render",
    "render_views",
    "rotation_to_camera",
    "surface_points",
]


def rotation_to_camera(theta_deg: float) -> torch.Tensor:
    """(3, 3) R with ``Pc = R @ P`` (object frame → camera frame at angle θ)."""
    return rotation_y(torch.tensor(math.radians(theta_deg), dtype=GEOMETRY_DTYPE))


def check_object(obj: object) -> SyntheticObject:
    """``obj`` as a :class:`~torch_eigview.datasets.shapes.SyntheticObject`; TypeError when it is none."""
    if not isinstance(obj, SyntheticObject):
        raise TypeError(f"obj must be a SyntheticObject (see make_object), got {type(obj).__name__}")
    return obj


def _cast(
    obj: SyntheticObject, theta: float, origin: torch.Tensor, direction: torch.Tensor, n_steps: int = 64
) -> tuple[torch.Tensor, torch.Tensor]:
    """First surface crossing of the rays ``origin + t·direction`` (camera frame, (N, 3)).

    Returns:
        ``(t, hit)``, (N,) each: the ray parameter of the crossing (NaN where none) and
        whether the ray meets the object.
    """
    th = math.radians(theta)
    cos, sin = math.cos(th), math.sin(th)
    f = obj.implicit

    def inside(o: torch.Tensor, d: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        o, d = o.to(t.dtype), d.to(t.dtype)
        # Camera frame (xc, yc, zc) -> object frame: X = xc cos - zc sin, Z = xc sin + zc cos.
        xc, yc, zc = (o[:, i, None] + t * d[:, i, None] for i in range(3))
        return f(xc * cos - zc * sin, yc, xc * sin + zc * cos) < 0

    radius = obj.radius * 1.05
    # Only the rays that meet the bounding sphere |o + t d| <= radius, on their chord.
    tc = -(origin * direction).sum(-1)
    miss2 = (origin + tc[:, None] * direction).square().sum(-1)
    rays = (miss2 < radius**2).nonzero().squeeze(1)
    o, d = origin[rays], direction[rays]
    half = (radius**2 - miss2[rays]).sqrt()
    t0 = tc[rays] - half
    # Samples 2·radius/n_steps apart (0.03 units): thinner parts than that could be missed.
    ts = t0[:, None] + (2 * half)[:, None] * torch.linspace(0.0, 1.0, n_steps, dtype=GEOMETRY_DTYPE)
    # The coarse march needs only the sign of f: float32 is 5x faster here than float64.
    ins = inside(o, d, ts.float())
    first = ins.to(torch.int8).argmax(dim=1)
    found = ins.any(dim=1) & (first > 0)
    lo = ts.gather(1, (first - 1).clamp_min(0)[:, None])
    hi = ts.gather(1, first[:, None])
    keep = found.nonzero().squeeze(1)
    lo, hi, o, d = lo[keep], hi[keep], o[keep], d[keep]
    for _ in range(36):  # the bracket shrinks from 0.03 units to below 1e-12
        mid = 0.5 * (lo + hi)
        inner = inside(o, d, mid)
        hi = torch.where(inner, mid, hi)
        lo = torch.where(inner, lo, mid)
    hit = torch.zeros(origin.shape[0], dtype=torch.bool)
    hit[rays[keep]] = True
    t = torch.full((origin.shape[0],), math.nan, dtype=GEOMETRY_DTYPE)
    t[rays[keep]] = 0.5 * (lo + hi)[:, 0]
    return t, hit


@dataclass(frozen=True)
class Render:
    """One rendered view.

    Attributes:
        image: (1, H, W) intensity in [0, 1], 0 on the background; with a backdrop
            (3, H, W) RGB, the object's gray intensity in every channel.
        depth: (H, W) depth along the viewing direction, +inf on the background.
        mask: (H, W) bool foreground.
        points: (H, W, 3) object-frame surface point of each pixel, NaN on the background.
        theta: the view's angle in degrees.
    """

    image: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor
    points: torch.Tensor
    theta: float


def pixel_grid(camera: Camera) -> tuple[torch.Tensor, torch.Tensor]:
    y, x = torch.meshgrid(
        torch.arange(camera.height, dtype=GEOMETRY_DTYPE),
        torch.arange(camera.width, dtype=GEOMETRY_DTYPE),
        indexing="ij",
    )
    return x, y


def surface_points(
    obj: SyntheticObject, theta: float, camera: Camera, x: torch.Tensor, y: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Object-frame points (..., 3), depth (...,) and hit mask (...,) of pixels (x, y)."""
    origin, direction = camera.rays(x.reshape(-1), y.reshape(-1))
    t, hit = _cast(obj, theta, origin, direction)
    pc = origin + t[:, None] * direction
    _, _, depth = camera.project(pc)
    points = pc @ rotation_to_camera(theta)  # P = R^T Pc
    return points.view(*x.shape, 3), torch.where(hit, depth, math.inf).view(x.shape), hit.view(x.shape)


def render(
    obj: SyntheticObject,
    theta: float,
    camera: Camera,
    *,
    dtype: torch.dtype = torch.float32,
    backdrop: Backdrop | None = None,
) -> Render:
    """Renders ``obj`` turned by ``theta`` degrees about its vertical axis.

    Args:
        obj: from :func:`~torch_eigview.datasets.shapes.make_object`.
        theta: rotation angle in degrees (the camera moves by −θ around the object).
        camera: :class:`~torch_eigview.datasets.cameras.AffineCamera`
            (:func:`~torch_eigview.datasets.cameras.OrthographicCamera`) or
            :class:`~torch_eigview.datasets.cameras.PerspectiveCamera`.
        dtype: floating dtype of the returned tensors (geometry is computed in float64).
        backdrop: None for the black background, or a
            :class:`~torch_eigview.datasets.backdrop.Backdrop` behind and under the object
            (then the image is RGB); the mask is the object's either way.

    Returns:
        :class:`Render` with (1, H, W) (or (3, H, W)) image, (H, W) depth and mask, (H, W, 3) points.

    Raises:
        ValueError: ``theta`` is not finite, or a perspective camera is inside the object.
    """
    obj = check_object(obj)
    cam = check_camera(camera)
    theta = check_number(theta, "theta")
    if not math.isfinite(theta):
        raise ValueError(f"theta={theta} must be a finite angle in degrees")
    cam.check_outside(obj.radius)
    x, y = pixel_grid(cam)
    points, depth, mask = surface_points(obj, theta, cam, x, y)
    image = torch.zeros(cam.height, cam.width, dtype=GEOMETRY_DTYPE)
    image[mask] = obj.intensity(points[mask]).clamp(0, 1)
    if backdrop is None:
        return Render(image[None].to(dtype), depth.to(dtype), mask, points.to(dtype), theta)
    if not isinstance(backdrop, Backdrop):
        raise TypeError(f"backdrop must be a Backdrop or None, got {type(backdrop).__name__}")
    rgb = image[None].repeat(3, 1, 1)
    origin, direction = cam.rays(x[~mask], y[~mask])
    rgb[:, ~mask] = backdrop.shade(origin, direction).T
    return Render(rgb.to(dtype), depth.to(dtype), mask, points.to(dtype), theta)


def render_views(
    obj: SyntheticObject,
    thetas: object,
    camera: Camera,
    *,
    dtype: torch.dtype = torch.float32,
    backdrop: Backdrop | None = None,
) -> torch.Tensor:
    """(T, 1, H, W) images of ``obj`` at the angles ``thetas`` (degrees, (T,) or a list);
    (T, 3, H, W) with a ``backdrop`` (see :func:`render`)."""
    angles = [float(t) for t in torch.as_tensor(thetas, dtype=GEOMETRY_DTYPE).reshape(-1)]
    if not angles:
        raise ValueError("thetas must hold at least one angle, got none")
    return torch.stack([render(obj, t, camera, dtype=dtype, backdrop=backdrop).image for t in angles])
