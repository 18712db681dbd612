"""A small ray-casting renderer for the synthetic objects.

Every pixel casts one ray of its camera (:mod:`torch_eigview.datasets.cameras`, whose
docstring gives the conventions); the first surface crossing is bracketed by sampling
``f`` along the ray inside the object's bounding sphere and refined by bisection. Depths
are +inf on the background.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

import torch_eigview._tuning as _tuning
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
    "render_many",
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
    t, hit = _cast_many(obj, [theta], origin, direction, n_steps)
    return t[0], hit[0]


def _cast_many(
    obj: SyntheticObject,
    thetas: list[float],
    origin: torch.Tensor,
    direction: torch.Tensor,
    n_steps: int = 64,
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`_cast` for T angles at once, ``(t, hit)`` (T, N) each, every ray's value as
    :func:`_cast` gives it alone (the same operations on it): the rays and their samples
    do not depend on the angle (the bounding sphere is centred on the axis), so the coarse
    march and the bisection run for a group of angles per call (as many as keep the
    group's samples within ``torch_eigview._tuning.MARCH_BATCH``), a few dozen torch calls
    per group instead of per view."""
    f = obj.implicit
    th = [math.radians(t) for t in thetas]
    n = origin.shape[0]

    def inside(
        o: torch.Tensor, d: torch.Tensor, t: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor
    ) -> torch.Tensor:
        o, d = o.to(t.dtype), d.to(t.dtype)
        cos, sin = cos.to(t.dtype), sin.to(t.dtype)  # each a double rounded once, as a Python scalar is
        # Camera frame (xc, yc, zc) -> object frame: X = xc cos - zc sin, Z = xc sin + zc cos.
        xc, yc, zc = (o[:, i, None] + t * d[:, i, None] for i in range(3))
        return f(xc * cos - zc * sin, yc, xc * sin + zc * cos) < 0

    cos_all = torch.tensor([math.cos(v) for v in th], dtype=GEOMETRY_DTYPE)
    sin_all = torch.tensor([math.sin(v) for v in th], dtype=GEOMETRY_DTYPE)
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
    # The coarse march needs only the sign of f, so it runs in float32 (half the memory
    # traffic of float64, twice the values per vector instruction); the bisection that
    # refines each crossing runs in float64.
    coarse = ts.float()
    t = torch.full((len(th), n), math.nan, dtype=GEOMETRY_DTYPE)
    hit = torch.zeros(len(th), n, dtype=torch.bool)
    # Angles in groups whose samples (and so their crossings) stay within the batch: the
    # memory of a call does not grow with the number of angles.
    chunk = max(1, _tuning.MARCH_BATCH // max(1, ts.numel()))
    for lo_t in range(0, len(th), chunk):
        sel = slice(lo_t, lo_t + chunk)
        ins = inside(o, d, coarse, cos_all[sel, None, None], sin_all[sel, None, None])  # (T', R, S)
        first = ins.to(torch.int8).argmax(dim=2)
        found = ins.any(dim=2) & (first > 0)
        del ins
        # The group's crossings, bracketed and bisected together: (angle, ray) pairs.
        angle, ray = found.nonzero().unbind(1)
        step = first[angle, ray]
        lo = ts[ray, (step - 1).clamp_min(0)][:, None]
        hi = ts[ray, step][:, None]
        o_r, d_r = o[ray], d[ray]
        cos, sin = cos_all[sel][angle, None], sin_all[sel][angle, None]
        for _ in range(36):  # the bracket shrinks from 0.03 units to below 1e-12
            mid = 0.5 * (lo + hi)
            inner = inside(o_r, d_r, mid, cos, sin)
            hi = torch.where(inner, mid, hi)
            lo = torch.where(inner, lo, mid)
        hit[lo_t + angle, rays[ray]] = True
        t[lo_t + angle, rays[ray]] = 0.5 * (lo + hi)[:, 0]
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
    return _surface(theta, camera, origin, direction, t, hit, x.shape)


def _surface(
    theta: float,
    camera: Camera,
    origin: torch.Tensor,
    direction: torch.Tensor,
    t: torch.Tensor,
    hit: torch.Tensor,
    shape: torch.Size,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """:func:`surface_points` from the rays' crossings ``t`` and ``hit`` (N,)."""
    pc = origin + t[:, None] * direction
    _, _, depth = camera.project(pc)
    points = pc @ rotation_to_camera(theta)  # P = R^T Pc
    return points.view(*shape, 3), torch.where(hit, depth, math.inf).view(shape), hit.view(shape)


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
    theta = check_number(theta, "theta")
    if not math.isfinite(theta):
        raise ValueError(f"theta={theta} must be a finite angle in degrees")
    return render_many(obj, [theta], camera, dtype=dtype, backdrop=backdrop)[0]


def render_many(
    obj: SyntheticObject,
    thetas: Sequence[float],
    camera: Camera,
    *,
    dtype: torch.dtype = torch.float32,
    backdrop: Backdrop | None = None,
) -> list[Render]:
    """:func:`render` at each of ``thetas`` (degrees), the same renders, with the rays
    cast for all angles at once (:func:`_cast_many`): a few dozen torch calls per batch of
    views instead of per view.

    Raises:
        ValueError: an angle that is not finite, or a perspective camera inside the object.
        TypeError: ``backdrop`` is neither None nor a Backdrop.
    """
    obj = check_object(obj)
    cam = check_camera(camera)
    angles = [check_number(t, "thetas") for t in thetas]
    if not all(math.isfinite(t) for t in angles):
        raise ValueError(f"thetas must be finite angles in degrees, got {angles}")
    if backdrop is not None and not isinstance(backdrop, Backdrop):
        raise TypeError(f"backdrop must be a Backdrop or None, got {type(backdrop).__name__}")
    cam.check_outside(obj.radius)
    if not angles:
        return []
    x, y = pixel_grid(cam)
    origin, direction = cam.rays(x.reshape(-1), y.reshape(-1))
    ts, hits = _cast_many(obj, angles, origin, direction)
    out = []
    for theta, t, hit in zip(angles, ts, hits, strict=True):
        points, depth, mask = _surface(theta, cam, origin, direction, t, hit, x.shape)
        image = torch.zeros(cam.height, cam.width, dtype=GEOMETRY_DTYPE)
        image[mask] = obj.intensity(points[mask]).clamp(0, 1)
        if backdrop is None:
            out.append(Render(image[None].to(dtype), depth.to(dtype), mask, points.to(dtype), theta))
            continue
        rgb = image[None].repeat(3, 1, 1)
        background = ~mask.reshape(-1)  # the rays of the call, not cast again
        rgb[:, ~mask] = backdrop.shade(origin[background], direction[background]).T
        out.append(Render(rgb.to(dtype), depth.to(dtype), mask, points.to(dtype), theta))
    return out


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
    return torch.stack([r.image for r in render_many(obj, angles, camera, dtype=dtype, backdrop=backdrop)])
