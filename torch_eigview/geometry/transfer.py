"""Point transfer through a trifocal tensor, and the epipoles and fundamental matrices it holds.

Conventions as :mod:`torch_eigview.geometry.trifocal`: ``T[i, j, k] = T_i^{jk}`` (HZ 2nd ed.)
with ``i`` the view-1 point index, ``j`` the view-2 line index and ``k`` the view-3 point
index; image points are pixels ``(x, y) = (column, row)``, homogeneous ``(x, y, 1)``;
everything is computed in float64 unless ``dtype`` says otherwise.
"""

from __future__ import annotations

import math

import torch

from torch_eigview.check import check_finite, check_float_tensor
from torch_eigview.geometry.trifocal import _as_matrix, _skew

__all__ = ["epipoles_from_tensor", "fundamental_from_tensor", "transfer_points"]

_LINES = ("perpendicular", "vertical", "paper")


def epipoles_from_tensor(
    T: torch.Tensor, *, dtype: torch.dtype = torch.float64
) -> tuple[torch.Tensor, torch.Tensor]:
    """The epipoles ``e2``, ``e3`` (images of camera 1's centre in views 2 and 3), HZ alg. 15.1.

    ``e2`` is the common perpendicular of the left null vectors of the ``T_i`` and ``e3``
    that of their right null vectors (by SVD, so exact data gives them to rounding).

    Args:
        T: (3, 3, 3) trifocal tensor.
        dtype: floating dtype of the computation and the results.

    Returns:
        ``(e2, e3)``, unit (3,) vectors, each up to sign.

    Raises:
        TypeError: ``T`` is not a floating tensor.
        ValueError: ``T`` is not a finite (3, 3, 3) tensor.
    """
    tt = _as_matrix(T, "T", (3, 3, 3), dtype)
    return _epipoles(tt)


def _epipoles(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    u, _, vh = torch.linalg.svd(t)  # batched over i
    left = u[:, :, 2]  # (3, 3): row i is the left null vector of T_i
    right = vh[:, 2, :]
    e2 = torch.linalg.svd(left)[2][-1]
    e3 = torch.linalg.svd(right)[2][-1]
    return e2, e3


def _fundamental(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    e2, e3 = _epipoles(t)
    f21 = _skew(e2) @ torch.einsum("ijk,k->ji", t, e3)
    f31 = _skew(e3) @ torch.einsum("ijk,j->ki", t, e2)
    return f21, f31


def fundamental_from_tensor(
    T: torch.Tensor, *, dtype: torch.dtype = torch.float64
) -> tuple[torch.Tensor, torch.Tensor]:
    """The fundamental matrices of views 1-2 and 1-3 from the tensor, HZ 15.22 / alg. 15.1.

    ``F21 = [e2]_x [T_1, T_2, T_3] e3`` and ``F31 = [e3]_x [T_1^T, T_2^T, T_3^T] e2``, so that
    ``x2^T F21 x1 = 0`` and ``x3^T F31 x1 = 0`` for matches (kornia's order).

    Args:
        T: (3, 3, 3) trifocal tensor (``<1, 2, 2>`` included).
        dtype: floating dtype of the computation and the results.

    Returns:
        ``(F21, F31)``, each (3, 3), each up to scale.

    Raises:
        TypeError: ``T`` is not a floating tensor.
        ValueError: ``T`` is not a finite (3, 3, 3) tensor.
    """
    tt = _as_matrix(T, "T", (3, 3, 3), dtype)
    return _fundamental(tt)


def _homogeneous(p: torch.Tensor) -> torch.Tensor:
    return torch.cat([p, torch.ones_like(p[..., :1])], dim=-1)


def _transfer(t: torch.Tensor, x1: torch.Tensor, line: torch.Tensor, rtol: float) -> torch.Tensor:
    """``x1^i l_j T_i^{jk}``, with NaN where the point is numerically 0/0 (the line is epipolar)."""
    x3 = torch.einsum("...i,...j,ijk->...k", x1, line, t)
    bound = x1.norm(dim=-1) * line.norm(dim=-1) * t.norm()
    degenerate = x3.norm(dim=-1) <= rtol * bound
    return torch.where(degenerate[..., None], torch.full_like(x3, math.nan), x3)


def transfer_points(
    T: torch.Tensor,
    p1: torch.Tensor,
    p2: torch.Tensor,
    *,
    line: str = "perpendicular",
    fundamental: torch.Tensor | None = None,
    dtype: torch.dtype = torch.float64,
) -> torch.Tensor:
    """Point transfer to view 3: ``x3^k = x1^i l2_j T_i^{jk}`` for a line ``l2`` through ``p2``.

    ``line`` picks ``l2``:

    * ``"perpendicular"`` (HZ 16.7): the line through ``p2`` perpendicular to the epipolar
      line ``F21 x1`` of ``p1``; never the epipolar line itself, so it is well conditioned
      for all but the degenerate points below.
    * ``"vertical"``: the line ``x = x2`` (``l2 = (1, 0, -x2)``), for both coordinates: the
      paper's relation for ``x''`` and the trilinearity it shares with the corrected
      ``y''`` relation ``y'' = (a^12 - x' a^32) / (a^13 - x' a^33)``.
    * ``"paper"``: the paper's two relations as intended: ``x''`` from the vertical line
      through ``x'``, ``x'' = (a^11 - x' a^31) / (a^13 - x' a^33)``, and ``y''`` from the
      horizontal line through ``y'``, ``y'' = (a^22 - y' a^32) / (a^23 - y' a^33)``, with
      ``a^jk = p^i alpha_i^{jk}`` and Shashua's ``alpha_i^{jk} = -T_i^{jk}`` (``j`` view 2,
      ``k`` view 3). The relations as printed,
      ``x'' = (x' a^31 - a^11) / (a^13 - x' a^33)`` and
      ``y'' = (y' a^32 - a^12) / (a^13 - y' a^33)``, are wrong: the first has the sign of
      its denominator flipped (it gives ``-x''``) and the second mixes the indices of the
      vertical-line trilinearity with ``y'`` (it transfers with the line ``x = y'``, which
      does not pass through ``p2``).

    Degenerate configurations give NaN (never an exception, so one bad match does not spoil
    a batch): where ``l2`` is (numerically) the epipolar line of ``p1`` the transfer is 0/0.
    The test is ``|x3| <= sqrt(eps) |x1| |l2| |T|_F``. For seed views on a horizontal
    circle this is every point on the horizon row for ``"paper"``'s ``y''`` (the horizontal
    line through ``p2`` is then the epipolar line); ``"vertical"`` fails where epipolar
    lines are vertical; ``"perpendicular"`` fails for ``p1`` at the epipole of camera 2 in
    view 1, whose epipolar line is undefined (no point on the baseline of cameras 1 and 2
    can be transferred by any line). A point transferred to infinity in view 3
    (``x3[2] = 0``) gives inf.

    Args:
        T: (3, 3, 3) tensor ``<1, 2, 3>`` in pixel coordinates (views 1, 2, 3 in index order).
        p1: (..., N, 2) pixels ``(x, y) = (column, row)`` in view 1.
        p2: (..., N, 2) their matches in view 2, the same shape as ``p1``.
        line: ``"perpendicular"``, ``"vertical"`` or ``"paper"``.
        fundamental: optional (3, 3) ``F21`` (``x2^T F21 x1 = 0``) for ``"perpendicular"``;
            default :func:`fundamental_from_tensor` of ``T``.
        dtype: floating dtype of the computation and the result.

    Returns:
        (..., N, 2) pixels ``(x, y)`` in view 3; NaN where degenerate.

    Raises:
        TypeError: an argument is not a floating tensor, or ``line`` is not a string.
        ValueError: a shape is wrong, a value is not finite, or ``line`` is unknown.
    """
    tt, a, b = _transfer_inputs(T, p1, p2, line, dtype)
    x1 = _homogeneous(a.to(dtype))
    x2, y2 = b[..., 0].to(dtype), b[..., 1].to(dtype)
    rtol = math.sqrt(torch.finfo(dtype).eps)
    if line == "perpendicular":
        if fundamental is None:
            f21 = _fundamental(tt)[0]
        else:
            f21 = _as_matrix(fundamental, "fundamental", (3, 3), dtype)
        return _perpendicular_transfer(tt, f21, x1, x2, y2, rtol)
    one, zero = torch.ones_like(x2), torch.zeros_like(x2)
    xv = _transfer(tt, x1, torch.stack([one, zero, -x2], dim=-1), rtol)
    if line == "vertical":
        return xv[..., :2] / xv[..., 2:]
    xh = _transfer(tt, x1, torch.stack([zero, one, -y2], dim=-1), rtol)
    return torch.stack([xv[..., 0] / xv[..., 2], xh[..., 1] / xh[..., 2]], dim=-1)


def _transfer_inputs(
    T: object, p1: object, p2: object, line: object, dtype: torch.dtype
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """:func:`transfer_points`'s tensor (in ``dtype``) and points, validated."""
    if not isinstance(line, str):
        raise TypeError(f"line must be a string, one of {_LINES}, got {type(line).__name__}")
    if line not in _LINES:
        raise ValueError(f"line must be one of {_LINES}, got {line!r}")
    tt = _as_matrix(T, "T", (3, 3, 3), dtype)
    a = check_float_tensor(p1, "p1")
    b = check_float_tensor(p2, "p2")
    if a.ndim < 2 or a.shape[-1] != 2:
        raise ValueError(f"p1 must have shape (..., N, 2), got shape {tuple(a.shape)}")
    if b.shape != a.shape:
        raise ValueError(f"p2 must have the shape of p1 {tuple(a.shape)}, got shape {tuple(b.shape)}")
    check_finite(a, "p1")
    check_finite(b, "p2")
    return tt, a, b


def _perpendicular_transfer(
    t: torch.Tensor, f21: torch.Tensor, x1: torch.Tensor, x2: torch.Tensor, y2: torch.Tensor, rtol: float
) -> torch.Tensor:
    """Transfer with the line through ``(x2, y2)`` perpendicular to the epipolar line
    ``F21 x1`` (HZ 16.7); ``x1`` (..., N, 3) homogeneous, the result (..., N, 2) pixels."""
    le = x1 @ f21.T  # epipolar line of p1 in view 2
    l2 = torch.stack([le[..., 1], -le[..., 0], -x2 * le[..., 1] + y2 * le[..., 0]], dim=-1)
    x3 = _transfer(t, x1, l2, rtol)
    # p1 at the epipole: F21 x1 is rounding noise and so is its perpendicular
    no_line = le[..., :2].norm(dim=-1) <= rtol * x1.norm(dim=-1) * f21.norm()
    x3 = torch.where(no_line[..., None], torch.full_like(x3, math.nan), x3)
    return x3[..., :2] / x3[..., 2:]
