"""Pose models: the coefficients that tie a novel view to two seed views.

Orthographic cameras rotating about the vertical axis (Sec. 3 of the paper): a world
point (X, Y, Z), with X measured from the rotation axis, projects to
``x - c = X cos(phi) + Z sin(phi)`` and ``y = Y`` in the view at angle ``phi``, where ``c``
is the image column of the axis. For seed views at 0 and ``alpha`` and a novel view at
``theta`` this gives Eq. 2 with Eq. 7's coefficients::

    x3 - c = a (x1 - c) + b (x2 - c),   a = sin(alpha - theta) / sin(alpha),
                                        b = sin(theta) / sin(alpha).
"""

from __future__ import annotations

import math

import torch

from torch_eigview.correspondence import Correspondence
from torch_eigview.errors import as_angle_tensor, check_alpha

__all__ = ["estimate_elevation", "orthographic_coefficients"]


def orthographic_coefficients(
    thetas: object, alpha: float, *, dtype: torch.dtype = torch.float64
) -> tuple[torch.Tensor, torch.Tensor]:
    """Eq. 7: the coefficients (a, b) of x3 = a·x1 + b·x2 for a batch of novel angles.

    Args:
        thetas: novel-view angles in degrees, measured from the first seed view: a number,
            a sequence or a tensor of shape (T,).
        alpha: angle of the second seed view in degrees; not a multiple of 180.
        dtype: floating dtype of the result.

    Returns:
        ``(a, b)``, each of shape (T,). ``theta = 0`` gives (1, 0) and ``theta = alpha``
        gives (0, 1): the seed views themselves.

    Raises:
        ValueError: ``alpha`` is a multiple of 180 degrees, or ``thetas`` is empty or not
            finite.

    Example:
        >>> a, b = orthographic_coefficients([0.0, 5.0], alpha=5.0)
        >>> torch.allclose(a, torch.tensor([1.0, 0.0], dtype=a.dtype), atol=1e-12)
        True
    """
    alpha = check_alpha(alpha)
    theta = as_angle_tensor(thetas, "thetas", dtype=torch.float64)
    sin_alpha = math.sin(math.radians(alpha))
    # alpha - theta in degrees first, so that a is exactly 0 at theta = alpha (as b is at 0).
    a = torch.sin(torch.deg2rad(alpha - theta)) / sin_alpha
    b = torch.sin(torch.deg2rad(theta)) / sin_alpha
    return a.to(dtype), b.to(dtype)


def estimate_elevation(
    correspondence: Correspondence,
    alpha: float,
    *,
    center: float | None = None,
    mask: torch.Tensor | None = None,
) -> torch.Tensor:
    """Least-squares elevation of a camera tilted towards the rotation axis, per object.

    A camera whose axis is tilted by ``elevation`` out of the plane perpendicular to the
    rotation axis still sees x follow Eq. 2, but y moves:
    ``y2 - y1 = -sin(elevation) (Z (cos(alpha) - 1) - X sin(alpha))`` with X, Z the
    point's coordinates recovered from x1, x2. This fits ``sin(elevation)`` to the
    vertical flow over the trusted pixels.

    Args:
        correspondence: (B, H, W) correspondences with ``vertical_12`` (a 2D flow, as
            :func:`~torch_eigview.correspondence.estimate_correspondence` returns).
        alpha: angle of the second seed view in degrees.
        center: column of the rotation axis; default ``(W - 1) / 2``.
        mask: optional (B, H, W) bool, pixels to use (e.g. the object's foreground).

    Returns:
        (B,) elevations in degrees.
    """
    alpha = check_alpha(alpha)
    if correspondence.vertical_12 is None:
        raise ValueError("correspondence.vertical_12 is None: estimating the elevation needs a 2D flow")
    d12 = correspondence.disparity_12.double()
    _, _, w = correspondence.shape
    c = (w - 1) / 2 if center is None else float(center)
    al = math.radians(alpha)
    big_x = torch.arange(w, dtype=torch.float64, device=d12.device) - c
    big_z = (big_x + d12 - big_x * math.cos(al)) / math.sin(al)
    basis = -(big_z * (math.cos(al) - 1) - big_x * math.sin(al))
    use = correspondence.valid_12 if mask is None else correspondence.valid_12 & mask.bool()
    v = correspondence.vertical_12.double()
    num = (basis * v * use).sum(dim=(-1, -2))
    den = (basis * basis * use).sum(dim=(-1, -2))
    if bool((den <= 0).any()):
        raise ValueError("no trusted correspondence with depth to estimate the elevation from")
    return torch.rad2deg(torch.asin((num / den).clamp(-1, 1))).to(correspondence.disparity_12.dtype)
