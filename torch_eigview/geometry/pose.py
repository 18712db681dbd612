"""Pose models: the coefficients that tie a novel view to two seed views.

Orthographic cameras rotating about the vertical axis (Sec. 3 of the paper): a world
point (X, Y, Z), with X measured from the rotation axis, projects to
``x - c = X cos(phi) + Z sin(phi)`` and ``y = Y`` in the view at angle ``phi``, where ``c``
is the image column of the axis. For seed views at 0 and ``alpha`` and a novel view at
``theta`` this gives Eq. 2 with Eq. 7's coefficients::

    x3 - c = a (x1 - c) + b (x2 - c),   a = sin(alpha - theta) / sin(alpha),
                                        b = sin(theta) / sin(alpha).

Affine cameras (Sec. 4): a camera ``x = M·X + t`` (M (2, 3), t (2,), pixels) turned with
the object by ``phi`` about the vertical axis images ``M·R(phi)·X + t``. Eq. 2 for all
points X at once is the linear system ``m·R(theta) = a·m + b·m·R(alpha)`` on the camera's
first row ``m`` (three equations, two unknowns), solved by least squares; the axis column
is ``c = t[0]``, and rows stay rows when the second row does not see the rotation
(``M[1]·R(phi) = M[1]``). :func:`affine_coefficients` reports the residual of both and
refuses a camera for which Eq. 2 cannot hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from torch_eigview.check import as_angle_tensor, check_alpha, check_number
from torch_eigview.geometry.correspondence import Correspondence, check_correspondence

__all__ = [
    "AffineCoefficients",
    "affine_coefficients",
    "estimate_elevation",
    "orthographic_coefficients",
    "rotation_y",
]


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


def rotation_y(phi: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotations by ``phi`` (radians, (...,)) about the vertical axis Y.

    ``R(phi) @ (X, Y, Z) = (X cos + Z sin, Y, Z cos − X sin)``: the object turned by phi as
    the camera sees it (the convention of :mod:`torch_eigview.datasets.cameras`).
    """
    c, s = torch.cos(phi), torch.sin(phi)
    z, o = torch.zeros_like(phi), torch.ones_like(phi)
    return torch.stack([c, z, s, z, o, z, -s, z, c], dim=-1).reshape(*phi.shape, 3, 3)


@dataclass(frozen=True)
class AffineCoefficients:
    """Eq. 2's coefficients for an affine camera, from :func:`affine_coefficients`.

    Attributes:
        a, b: (T,) coefficients of ``x3 − c = a (x1 − c) + b (x2 − c)``.
        center: column ``c`` of the rotation axis in the image (``t[0]``).
        residual: (T,) relative residual of the system per novel angle: the largest of
            ``|m R(θ) − a m − b m R(α)| / |m|`` (Eq. 2 for x) and
            ``|M[1] R(φ) − M[1]| / |M[1]|`` at φ = θ and α (rows stay rows).
    """

    a: torch.Tensor
    b: torch.Tensor
    center: float
    residual: torch.Tensor


def _check_affine_camera(camera: object) -> tuple[torch.Tensor, torch.Tensor]:
    """(M (2, 3), t (2,)) float64 of a (2, 3), (2, 4) or (3, 4) affine camera matrix."""
    if not isinstance(camera, torch.Tensor):
        raise TypeError(
            f"camera must be a torch.Tensor of shape (2, 3), (2, 4) or (3, 4), got {type(camera).__name__}"
        )
    if not camera.is_floating_point():
        raise TypeError(f"camera must have a floating dtype, got {camera.dtype}")
    p = camera.detach().to("cpu", torch.float64)  # a small constant: solved on the CPU
    if p.shape not in ((2, 3), (2, 4), (3, 4)):
        raise ValueError(
            f"camera must have shape (2, 3), (2, 4) or (3, 4) (an affine camera), got {tuple(p.shape)}"
        )
    if not bool(torch.isfinite(p).all()):
        raise ValueError("camera must be finite, got NaN or infinite entries")
    if p.shape[0] == 3:
        last = torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.float64)
        if (
            not torch.allclose(p[2], last * p[2, 3], rtol=0, atol=1e-12 * float(p.abs().max()))
            or p[2, 3] == 0
        ):
            raise ValueError(
                f"camera of shape (3, 4) must be affine, last row (0, 0, 0, s), got {p[2].tolist()}"
            )
        p = p[:2] / p[2, 3]
    m = p[:, :3]
    t = p[:, 3] if p.shape[1] == 4 else torch.zeros(2, dtype=torch.float64)
    sv = torch.linalg.svdvals(m)
    if float(sv[1]) <= 1e-12 * float(sv[0]):
        raise ValueError(
            f"camera is singular: its (2, 3) matrix M must have rank 2, got singular values {sv.tolist()}"
        )
    return m, t


def affine_coefficients(
    camera: torch.Tensor,
    alpha: float,
    thetas: object,
    *,
    tol: float = 1e-9,
    dtype: torch.dtype = torch.float64,
) -> AffineCoefficients:
    """Sec. 4's affine camera: Eq. 2's a and b from the camera matrix, by least squares.

    The first seed view is ``x = M·X + t``, the second the camera turned by ``alpha``
    about the vertical axis (T1 = R(alpha)), the novel one turned by ``theta``
    (T2 = R(theta)). Eq. 2, ``x3 − c = a (x1 − c) + b (x2 − c)``, holds for every point
    exactly when ``m R(theta) = a m + b m R(alpha)`` for the first row ``m`` of M, with
    ``c = t[0]``; this solves that system for (a, b) in the least-squares sense and
    reports the residual. It is zero for every camera whose x does not depend on the
    height and whose y does not see the rotation, and then (a, b) are Eq. 7's (for an
    orthographic camera exactly); otherwise Eq. 2 cannot hold and this raises.

    Args:
        camera: (2, 3) M, or (2, 4) ``[M | t]``, or (3, 4) with last row (0, 0, 0, 1).
        alpha: angle of the second seed view in degrees.
        thetas: novel angles in degrees, a number, a sequence or a (T,) tensor.
        tol: largest relative residual accepted.
        dtype: floating dtype of ``a``, ``b`` and ``residual``.

    Returns:
        :class:`AffineCoefficients` with (T,) ``a``, ``b``, ``residual`` and ``center``.

    Raises:
        TypeError: ``camera`` is not a float tensor.
        ValueError: a singular camera (rank of M below 2), a camera that does not see
            the rotation (``m`` has no horizontal part), coincident seed cameras
            (``alpha`` a multiple of 180), or a residual above ``tol``: the camera's x
            depends on the height Y or its y moves with the rotation, so Eq. 2 with one
            (a, b) cannot hold.

    Example:
        >>> cam = torch.tensor([[50.0, 0, 0, 31.5], [0, -50.0, 0, 31.5]])
        >>> coef = affine_coefficients(cam, alpha=10.0, thetas=[0.0, 5.0, 10.0])
        >>> torch.allclose(coef.a, orthographic_coefficients([0.0, 5.0, 10.0], 10.0)[0])
        True
    """
    m, t = _check_affine_camera(camera)
    alpha = check_alpha(alpha)
    if not (isinstance(tol, (int, float)) and not isinstance(tol, bool) and tol >= 0):
        raise ValueError(f"tol must be a non-negative number, got {tol!r}")
    theta = as_angle_tensor(thetas, "thetas", dtype=torch.float64).cpu()
    row, row_y = m[0], m[1]
    if float(torch.hypot(row[0], row[2])) <= 1e-12 * float(row.norm()):
        raise ValueError(
            f"camera's first row {row.tolist()} must have a horizontal part (M[0, 0], M[0, 2]): "
            "its x does not see the rotation about the vertical axis"
        )
    r_alpha = rotation_y(torch.tensor(math.radians(alpha), dtype=torch.float64))
    r_theta = rotation_y(torch.deg2rad(theta))  # (T, 3, 3)
    # Eq. 2 for every point: rows m R(theta) = a m + b m R(alpha); unknowns (a, b).
    basis = torch.stack([row, row @ r_alpha], dim=1)  # (3, 2)
    target = row @ r_theta  # (T, 3)
    sol = torch.linalg.lstsq(basis.expand(theta.numel(), 3, 2), target[..., None]).solution[..., 0]
    res_x = (basis @ sol[..., None])[..., 0].sub(target).norm(dim=-1) / row.norm()
    # Rows stay rows at the novel angle and between the seeds.
    res_y = (
        torch.maximum((row_y @ r_theta - row_y).norm(dim=-1), (row_y @ r_alpha - row_y).norm(dim=-1))
        / row_y.norm()
    )
    residual = torch.maximum(res_x, res_y)
    worst = int(residual.argmax())
    if float(residual[worst]) > tol:
        why = (
            "the camera's x depends on the height Y (M[0, 1] != 0)"
            if float(res_x[worst]) > tol
            else "the camera's y moves with the rotation (M[1] has a horizontal part): rows do not stay rows"
        )
        raise ValueError(
            f"Eq. 2 cannot hold for this camera: relative residual {float(residual[worst]):.3g} > tol={tol} "
            f"at theta={float(theta[worst])}; {why}"
        )
    return AffineCoefficients(sol[:, 0].to(dtype), sol[:, 1].to(dtype), float(t[0]), residual.to(dtype))


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
            :func:`~torch_eigview.geometry.flow.estimate_correspondence` returns).
        alpha: angle of the second seed view in degrees.
        center: column of the rotation axis; default ``(W - 1) / 2``.
        mask: optional (B, H, W) bool, pixels to use (e.g. the object's foreground).

    Returns:
        (B,) elevations in degrees. A fit outside the model's range saturates at ±90
        (``sin(elevation)`` clamped to [-1, 1]), which is not a camera any warp accepts:
        :func:`~torch_eigview.synthesis.pair_geometry` treats it as no estimate.

    Raises:
        TypeError: ``correspondence`` is not a :class:`Correspondence`.
        ValueError: no ``vertical_12``, a bad ``alpha``, ``center`` or ``mask``, or no
            trusted pixel with depth under the mask.
    """
    correspondence = check_correspondence(correspondence)
    alpha = check_alpha(alpha)
    if center is not None and not math.isfinite(check_number(center, "center")):
        raise ValueError(f"center={center!r} must be finite or None")
    if mask is not None and (
        not isinstance(mask, torch.Tensor) or mask.shape != correspondence.disparity_12.shape
    ):
        got = tuple(mask.shape) if isinstance(mask, torch.Tensor) else type(mask).__name__
        raise ValueError(
            f"mask must be a tensor of shape {tuple(correspondence.disparity_12.shape)}, got {got}"
        )
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
