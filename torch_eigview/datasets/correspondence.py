"""Exact correspondences between rendered views of a synthetic object.

They follow from the 3D point of each pixel: it is projected into the other view, and it
is visible there when the other view's ray through that (sub-pixel) position first meets
the surface at that point. Conventions as in :mod:`torch_eigview.datasets.cameras`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from torch_eigview.check import check_number
from torch_eigview.datasets.cameras import GEOMETRY_DTYPE, AffineCamera, Camera, check_camera
from torch_eigview.datasets.renderer import (
    Render,
    check_object,
    pixel_grid,
    render,
    rotation_to_camera,
    surface_points,
)
from torch_eigview.datasets.shapes import SyntheticObject
from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity

__all__ = [
    "ViewCorrespondence",
    "exact_correspondence",
    "exact_correspondence_2d",
    "seen_error",
    "view_correspondence",
]


@dataclass(frozen=True)
class ViewCorrespondence:
    """Where each pixel of view A lands in view B.

    Attributes:
        x_b: (H, W) column in view B of view A's surface point at each pixel (NaN off the object).
        y_b: (H, W) row in view B.
        visible: (H, W) bool, the point is in view B's image and not hidden there.
        mask_a: (H, W) bool foreground of view A.
    """

    x_b: torch.Tensor
    y_b: torch.Tensor
    visible: torch.Tensor
    mask_a: torch.Tensor


def view_correspondence(
    obj: SyntheticObject,
    theta_a: float,
    theta_b: float,
    camera: Camera,
    *,
    tolerance: float = 1e-4,
    view_a: Render | None = None,
) -> ViewCorrespondence:
    """Exact correspondences from view A (angle ``theta_a``) to view B (``theta_b``).

    Each foreground pixel's object-frame point is rotated into view B and projected; it is
    visible when view B's ray through that sub-pixel position meets the object first at
    that point (within ``tolerance`` object units along the ray), which is an exact
    z-buffer test.

    Args:
        obj: the object.
        theta_a, theta_b: the two views' angles in degrees.
        camera: the camera of both views.
        tolerance: depth tolerance of the visibility test, object units.
        view_a: the render of view A, if already at hand (saves one ray cast).

    Returns:
        :class:`ViewCorrespondence` with (H, W) float64 maps.
    """
    obj = check_object(obj)
    cam = check_camera(camera)
    theta_a = check_number(theta_a, "theta_a")
    theta_b = check_number(theta_b, "theta_b")
    cam.check_outside(obj.radius)
    if view_a is None:
        x, y = pixel_grid(cam)
        points, _, mask = surface_points(obj, theta_a, cam, x, y)
    else:
        points, mask = view_a.points.to(GEOMETRY_DTYPE), view_a.mask
    pc = points @ rotation_to_camera(theta_b).T
    x_b, y_b, depth_b = cam.project(pc)
    h, w = cam.height, cam.width
    inside = mask & (x_b >= -0.5) & (x_b <= w - 0.5) & (y_b >= -0.5) & (y_b <= h - 0.5)
    visible = torch.zeros_like(mask)
    if bool(inside.any()):
        _, first, hit = surface_points(obj, theta_b, cam, x_b[inside], y_b[inside])
        # The ray through the point meets the surface at the point or before it.
        visible[inside] = hit & (depth_b[inside] <= first + tolerance)
    return ViewCorrespondence(x_b, y_b, visible, mask)


def exact_correspondence(
    obj: SyntheticObject, alpha: float, camera: AffineCamera, *, theta_1: float = 0.0
) -> Correspondence:
    """The exact :class:`~torch_eigview.geometry.correspondence.Correspondence` of seed views θ1 and θ1 + α.

    For :func:`~torch_eigview.datasets.cameras.OrthographicCamera`, where points keep
    their row, so that :class:`~torch_eigview.warp.novel_view.NovelViewWarp` and
    :func:`~torch_eigview.synthesis.synthesize_views` (as a ``PairGeometry``) can use
    it in place of optical flow. Every foreground pixel is valid, hidden in the other view
    or not (its correspondence is known exactly; the warp's z-buffer sorts out which
    surface shows). Background pixels get the disparity of the plane through the
    rotation axis and are invalid.

    Returns:
        A (1, H, W) float32 :class:`~torch_eigview.geometry.correspondence.Correspondence`.

    Raises:
        ValueError: the camera moves rows (it is not orthographic about the vertical axis).
    """
    cam = check_camera(camera)
    if (
        not isinstance(cam, AffineCamera)
        or float(cam.P[0, 1].abs() + cam.P[1, 0].abs() + cam.P[1, 2].abs()) > 0
    ):
        raise ValueError("camera must be an OrthographicCamera (rows must stay rows) for a Correspondence")
    check_number(alpha, "alpha")
    maps = []
    w = cam.width
    cols = torch.arange(w, dtype=GEOMETRY_DTYPE).expand(cam.height, w)
    c = float(cam.P[0, 3])  # the column of the rotation axis
    for ta, tb in ((theta_1, theta_1 + alpha), (theta_1 + alpha, theta_1)):
        corr = view_correspondence(obj, ta, tb, cam)
        plane = (cols - c) * (math.cos(math.radians(tb - ta)) - 1)
        disparity = torch.where(corr.mask_a, corr.x_b - cols, plane)
        maps.append((disparity.to(torch.float32), corr.mask_a))
    (d12, v12), (d21, v21) = maps
    return correspondence_from_disparity(d12, d21, valid_12=v12, valid_21=v21)


def exact_correspondence_2d(
    obj: SyntheticObject, alpha: float, camera: Camera, *, theta_1: float = 0.0
) -> Correspondence:
    """The exact 2D :class:`~torch_eigview.geometry.correspondence.Correspondence` of seed views θ1 and θ1 + α.

    For any camera (points may move in both coordinates, as with
    :class:`~torch_eigview.datasets.cameras.PerspectiveCamera`): ``disparity`` and
    ``vertical`` hold the column and row shifts of each foreground pixel's surface
    point, both directions; foreground pixels are valid, the background has zero shift
    and is invalid.

    Returns:
        A (1, H, W) float32 :class:`~torch_eigview.geometry.correspondence.Correspondence`
        with ``vertical_12`` and ``vertical_21``.
    """
    cam = check_camera(camera)
    check_number(alpha, "alpha")
    x, y = pixel_grid(cam)
    out = []
    for ta, tb in ((theta_1, theta_1 + alpha), (theta_1 + alpha, theta_1)):
        corr = view_correspondence(obj, ta, tb, cam)
        dx = torch.where(corr.mask_a, corr.x_b - x, 0.0).to(torch.float32)
        dy = torch.where(corr.mask_a, corr.y_b - y, 0.0).to(torch.float32)
        out.append((dx[None], dy[None], corr.mask_a[None]))
    (d12, v12, m12), (d21, v21, m21) = out
    return Correspondence(d12, d21, m12, m21, v12, v21)


def seen_error(
    obj: SyntheticObject, camera: Camera, view: torch.Tensor, theta: float, seed_angles: tuple[float, ...]
) -> float:
    """Per-pixel mean absolute error of ``view`` (1, H, W) against the render at ``theta``.

    Over the object's pixels at ``theta`` that every seed view (at ``seed_angles``) sees:
    the paper's per-pixel error "except occluded pixels". Intensities are in [0, 1], so
    0.01 is 1%.

    Raises:
        ValueError: no pixel is seen by every seed view.
    """
    truth = render(obj, theta, camera)
    both = truth.mask.clone()
    for seed in seed_angles:
        both &= view_correspondence(obj, theta, seed, camera, view_a=truth).visible
    if not bool(both.any()):
        raise ValueError(f"no pixel at theta={theta} is seen by every seed view {seed_angles}")
    return float((view[0].to(truth.image.dtype) - truth.image[0]).abs()[both].mean())
