"""The trifocal tensor of a novel perspective view (Sec. 4 of the paper).

After Shashua & Avidan, "Novel view synthesis by cascading trilinear tensors": the tensor
``<1, 2, 2>`` of the two seed views is moved to the tensor ``<1, 2, psi>`` of a novel
view by a rotation and a translation (the paper's "tensorial operator"), and the matches
``(p1, p2)`` of the seed views are transferred to the novel view through it
(:mod:`torch_eigview.geometry.transfer`).

Conventions:

* Indices follow Hartley & Zisserman (HZ, 2nd ed.): ``T[i, j, k] = T_i^{jk}`` with ``i``
  the view-1 point index, ``j`` the view-2 line index and ``k`` the view-3 point index, so
  that ``x3^k = x1^i l2_j T_i^{jk}`` for a line ``l2`` through ``x2`` (HZ 16.7) and
  ``[x2]_x (sum_i x1^i T_i) [x3]_x = 0`` (HZ 16.3), where ``T_i = T[i]`` is 3x3.
* ``T_i^{qr} = (-1)^(i+1) det[~a^i; b^q; c^r]`` (HZ 17.12), ``~a^i`` being ``P1`` without
  row ``i`` and ``b^q``, ``c^r`` rows of ``P2``, ``P3``. For ``P1 = [I | 0]``,
  ``P2 = [A | a]`` and ``P3 = [B | b]`` this is ``T_i^{jk} = A[j, i] b[k] - a[j] B[k, i]``.
  Shashua's ``alpha_i^{jk}`` (``j`` the view-2 index, ``k`` the view-3 index) is the
  negative of this tensor; ratios (all transfers) do not see the sign, but the relative sign
  of the two terms of :func:`novel_view_tensor` does (there ``+t``, the paper's ``-t``).
* Image points are pixels ``(x, y) = (column, row)``, homogeneous ``(x, y, 1)``; an image
  homography ``x' = H x`` maps a tensor to
  ``T'_i^{jk} = (H1^-1)^{i'}_i H2^j_{j'} H3^k_{k'} T_{i'}^{j'k'}`` (:func:`transform_tensor`).
* Cameras are (3, 4) matrices ``P = K [R | t]`` mapping world points ``X`` to ``P X``
  (``R``, ``t`` world to camera). Everything is computed in float64 unless ``dtype`` says
  otherwise; any floating input is accepted. Tensors are not normalised: their scale is that
  of the determinants (the tensor is defined up to scale).
"""

from __future__ import annotations

import math

import torch

from torch_eigview.check import check_finite, check_float_tensor

__all__ = [
    "novel_view_tensor",
    "novel_view_tensor_from_cameras",
    "seed_tensor",
    "tensor_from_fundamental",
    "transform_tensor",
    "trifocal_tensor",
]


def _tol(dtype: torch.dtype) -> float:
    """Relative rank tolerance for data that arrived in ``dtype``."""
    return 100.0 * torch.finfo(dtype).eps


def _as_matrix(x: object, name: str, shape: tuple[int, ...], dtype: torch.dtype) -> torch.Tensor:
    """A finite floating tensor of exactly ``shape``, converted to ``dtype``."""
    t = check_float_tensor(x, name)
    if tuple(t.shape) != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {tuple(t.shape)}")
    check_finite(t, name)
    return t.to(dtype)


def _check_camera(x: object, name: str, dtype: torch.dtype) -> torch.Tensor:
    """A finite (3, 4) camera of rank 3 whose left 3x3 block is invertible (a finite centre)."""
    p = _as_matrix(x, name, (3, 4), dtype)
    tol = _tol(check_float_tensor(x, name).dtype)
    s = torch.linalg.svdvals(p)
    if not bool(s[0] > 0) or float(s[2] / s[0]) <= tol:
        raise ValueError(
            f"{name} is a singular camera: a (3, 4) camera matrix must have rank 3, got singular values {s.tolist()}"
        )
    m = torch.linalg.svdvals(p[:, :3])
    if float(m[2] / m[0]) <= tol:
        raise ValueError(
            f"{name} is a singular camera: its left 3x3 block must be invertible (a finite camera centre), got singular values {m.tolist()}"
        )
    return p


def _check_rotation(x: object, name: str, dtype: torch.dtype) -> torch.Tensor:
    """A (3, 3) rotation: orthonormal with determinant +1, to a tolerance of the input dtype."""
    r = _as_matrix(x, name, (3, 3), dtype)
    tol = max(1e-9, 1e3 * torch.finfo(check_float_tensor(x, name).dtype).eps)
    err = float((r.T @ r - torch.eye(3, dtype=dtype, device=r.device)).abs().max())
    det = float(torch.linalg.det(r))
    if err > tol or abs(det - 1.0) > tol:
        raise ValueError(
            f"{name} must be a rotation matrix (orthonormal, det +1), got max |{name}^T {name} - I| = {err:.3g} and det = {det:.6g}"
        )
    return r


def _camera_centre(p: torch.Tensor) -> torch.Tensor:
    """Unit 4-vector spanning the right null space of a rank-3 (3, 4) camera."""
    return torch.linalg.svd(p)[2][-1]


def _skew(v: torch.Tensor) -> torch.Tensor:
    """``[v]_x``, the (3, 3) matrix of the cross product ``v x .``."""
    z = torch.zeros((), dtype=v.dtype, device=v.device)
    return torch.stack(
        [torch.stack([z, -v[2], v[1]]), torch.stack([v[2], z, -v[0]]), torch.stack([-v[1], v[0], z])]
    )


def _tensor(p1: torch.Tensor, p2: torch.Tensor, p3: torch.Tensor) -> torch.Tensor:
    """HZ 17.12 for validated cameras: all 27 (4, 4) determinants at once."""
    rows = torch.tensor([[1, 2], [0, 2], [0, 1]], device=p1.device)
    a = p1[rows]  # (3, 2, 4): ~a^i
    m = torch.cat(
        [
            a[:, None, None].expand(3, 3, 3, 2, 4),
            p2[None, :, None, None, :].expand(3, 3, 3, 1, 4),
            p3[None, None, :, None, :].expand(3, 3, 3, 1, 4),
        ],
        dim=-2,
    )
    sign = torch.tensor([1.0, -1.0, 1.0], dtype=p1.dtype, device=p1.device)
    return sign[:, None, None] * torch.linalg.det(m)


def trifocal_tensor(
    P1: torch.Tensor, P2: torch.Tensor, P3: torch.Tensor, *, dtype: torch.dtype = torch.float64
) -> torch.Tensor:
    """The trifocal tensor of three cameras, HZ eq. 17.12.

    ``T_i^{qr} = (-1)^(i+1) det[~a^i; b^q; c^r]`` with ``~a^i`` the camera ``P1`` without
    row ``i`` and ``b^q``, ``c^r`` the rows ``q``, ``r`` of ``P2``, ``P3``. Any cameras with
    finite centres (``P1`` need not be ``[I | 0]``); ``P3`` may equal ``P2`` (the seed
    tensor ``<1, 2, 2>``, :func:`seed_tensor`).

    Args:
        P1: (3, 4) camera of view 1.
        P2: (3, 4) camera of view 2; its centre differs from ``P1``'s.
        P3: (3, 4) camera of view 3.
        dtype: floating dtype of the computation and the result.

    Returns:
        (3, 3, 3) tensor ``T[i, j, k] = T_i^{jk}``: ``i`` view 1, ``j`` view 2, ``k`` view 3.

    Raises:
        TypeError: a camera is not a floating tensor.
        ValueError: a camera is not a finite (3, 4) matrix, is singular (rank < 3, or its left
            3x3 block is singular: a camera at infinity), or ``P1`` and ``P2`` share their
            centre ("coincident seed cameras").

    Example:
        >>> P1 = torch.eye(3, 4, dtype=torch.float64)
        >>> P2 = torch.cat([torch.eye(3), torch.tensor([[1.0], [0.0], [0.0]])], 1).double()
        >>> trifocal_tensor(P1, P2, P2).shape
        torch.Size([3, 3, 3])
    """
    p1 = _check_camera(P1, "P1", dtype)
    p2 = _check_camera(P2, "P2", dtype)
    p3 = _check_camera(P3, "P3", dtype)
    c1, c2 = _camera_centre(p1), _camera_centre(p2)
    sine = math.sqrt(max(0.0, 1.0 - float(c1 @ c2) ** 2))
    tol = 10 * _tol(torch.promote_types(P1.dtype, P2.dtype))
    if sine <= max(tol, 1e-12):
        raise ValueError(
            f"P1 and P2 are coincident seed cameras: their centres must differ, got the same centre {(c1[:3] / c1[3]).tolist()}"
        )
    return _tensor(p1, p2, p3)


def seed_tensor(P1: torch.Tensor, P2: torch.Tensor, *, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """The degenerate tensor ``<1, 2, 2>`` of the seed pair: ``trifocal_tensor(P1, P2, P2)``.

    For ``P1 = [I | 0]`` and ``P2 = [A | a]`` it is ``T_i^{jk} = A[j, i] a[k] - a[j] A[k, i]``,
    antisymmetric in ``(j, k)``; it is the starting point of :func:`novel_view_tensor`.

    Args:
        P1: (3, 4) camera of seed view 1.
        P2: (3, 4) camera of seed view 2.
        dtype: floating dtype of the computation and the result.

    Returns:
        (3, 3, 3) tensor ``<1, 2, 2>``.

    Raises:
        TypeError, ValueError: as :func:`trifocal_tensor`.
    """
    return trifocal_tensor(P1, P2, P2, dtype=dtype)


def tensor_from_fundamental(
    F: torch.Tensor, *, dtype: torch.dtype = torch.float64
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The seed tensor ``<1, 2, 2>`` of an uncalibrated pair, from its fundamental matrix.

    ``F`` (``x2^T F x1 = 0``, as kornia's ``fundamental_from_projections(P1, P2)``) fixes the
    cameras only up to a projective transformation of space. This picks the canonical frame
    (HZ 9.14) ``P1 = [I | 0]``, ``P2 = [A | e2]`` with ``e2`` the epipole in view 2
    (``F^T e2 = 0``, unit norm) and ``A = [e2]_x F``, and returns
    ``T122_i^{jk} = A[j, i] e2[k] - e2[j] A[k, i]`` (``= trifocal_tensor`` of that frame's
    ``P1, P2, P2``; Shashua writes the negative ``e2^j A^k_i - e2^k A^j_i``). ``A`` is
    singular (rank 2), so ``P2`` is a camera at infinity of the projective frame: a rotation
    and translation given to :func:`novel_view_tensor` in this frame are projective, not
    Euclidean, motions.

    Args:
        F: (3, 3) fundamental matrix of rank 2. If its smallest singular value is not exactly
            zero, ``e2`` is the least-squares left null vector (that of the nearest rank-2
            matrix) and ``A`` is the same as for that matrix.
        dtype: floating dtype of the computation and the results.

    Returns:
        ``(T122, A, e2)``: (3, 3, 3), (3, 3) and (3,).

    Raises:
        TypeError: ``F`` is not a floating tensor.
        ValueError: ``F`` is not a finite (3, 3) matrix, or its rank is below 2.
    """
    f = _as_matrix(F, "F", (3, 3), dtype)
    u, s, _ = torch.linalg.svd(f)
    if not bool(s[0] > 0) or float(s[1] / s[0]) <= _tol(F.dtype):
        raise ValueError(f"F must be a fundamental matrix of rank 2, got singular values {s.tolist()}")
    e2 = u[:, 2]
    a = _skew(e2) @ f
    t = torch.einsum("ji,k->ijk", a, e2) - torch.einsum("j,ki->ijk", e2, a)
    return t, a, e2


def novel_view_tensor(
    T122: torch.Tensor,
    A: torch.Tensor,
    R: torch.Tensor,
    t: torch.Tensor,
    *,
    dtype: torch.dtype = torch.float64,
) -> torch.Tensor:
    """The paper's "tensorial operator": the tensor ``<1, 2, psi>`` of a novel view.

    In the frame ``P1 = [I | 0]``, ``P2 = [A | a]``, the novel camera is camera 2 moved by
    the rotation ``R`` and then the translation ``t`` (in camera 2's frame):
    ``P_psi = [R A | R a + t]``. Its tensor with the seed views follows from the seed tensor
    ``T122 = <1, 2, 2>`` without ``a``::

        G_i^{jk} = R[k, l] T122_i^{jl} + t[k] A[j, i]

    (HZ sign; with Shashua's tensor ``alpha = -T`` it reads ``R^k_l alpha_i^{jl} - t^k a^j_i``,
    the paper's form). ``R = I, t = 0`` gives ``T122`` back. The result equals
    ``trifocal_tensor(P1, P2, P_psi)`` exactly, not only up to scale, when ``T122`` and ``A``
    come from the same ``P2`` (:func:`seed_tensor` of ``[I | 0]`` and ``[A | a]``, or
    :func:`tensor_from_fundamental`): scaling ``P2`` scales ``T122`` quadratically and ``A``
    linearly, and changes what ``t`` means. For pixel coordinates and general seed cameras
    see :func:`novel_view_tensor_from_cameras`.

    Args:
        T122: (3, 3, 3) seed tensor ``<1, 2, 2>`` in the frame ``P1 = [I | 0]``.
        A: (3, 3) left block of ``P2`` (the homography of the plane at infinity, 1 to 2).
        R: (3, 3) rotation (orthonormal, det +1) of the novel camera relative to camera 2.
        t: (3,) translation of the novel camera, in camera 2's frame after ``R``.
        dtype: floating dtype of the computation and the result.

    Returns:
        (3, 3, 3) tensor ``<1, 2, psi>``.

    Raises:
        TypeError: an argument is not a floating tensor.
        ValueError: a shape is wrong, a value is not finite, or ``R`` is not a rotation.
    """
    t122 = _as_matrix(T122, "T122", (3, 3, 3), dtype)
    a = _as_matrix(A, "A", (3, 3), dtype)
    r = _check_rotation(R, "R", dtype)
    tt = _as_matrix(t, "t", (3,), dtype)
    return torch.einsum("kl,ijl->ijk", r, t122) + torch.einsum("k,ji->ijk", tt, a)


def transform_tensor(
    T: torch.Tensor,
    H1: torch.Tensor,
    H2: torch.Tensor,
    H3: torch.Tensor,
    *,
    dtype: torch.dtype = torch.float64,
) -> torch.Tensor:
    """The tensor in new image coordinates ``x_n' = H_n x_n`` of the three views.

    ``T'_i^{jk} = (H1^-1)[i', i] H2[j, j'] H3[k, k'] T_{i'}^{j'k'}`` (points transform with
    ``H``, lines with ``H^-T``). With ``H = K`` this takes a tensor of normalised camera
    coordinates to pixels.

    Args:
        T: (3, 3, 3) tensor.
        H1: (3, 3) invertible homography of view 1.
        H2: (3, 3) homography of view 2.
        H3: (3, 3) homography of view 3.
        dtype: floating dtype of the computation and the result.

    Returns:
        (3, 3, 3) tensor in the new coordinates.

    Raises:
        TypeError: an argument is not a floating tensor.
        ValueError: a shape is wrong, a value is not finite, or ``H1`` is singular.
    """
    tt = _as_matrix(T, "T", (3, 3, 3), dtype)
    h1 = _as_matrix(H1, "H1", (3, 3), dtype)
    h2 = _as_matrix(H2, "H2", (3, 3), dtype)
    h3 = _as_matrix(H3, "H3", (3, 3), dtype)
    s = torch.linalg.svdvals(h1)
    if not bool(s[0] > 0) or float(s[2] / s[0]) <= _tol(H1.dtype):
        raise ValueError(f"H1 must be an invertible (3, 3) homography, got singular values {s.tolist()}")
    return torch.einsum("ai,jb,kc,abc->ijk", torch.linalg.inv(h1), h2, h3, tt)


def novel_view_tensor_from_cameras(
    K: torch.Tensor,
    R1: torch.Tensor,
    t1: torch.Tensor,
    R2: torch.Tensor,
    t2: torch.Tensor,
    R: torch.Tensor,
    t: torch.Tensor,
    *,
    dtype: torch.dtype = torch.float64,
) -> torch.Tensor:
    """The pixel-coordinate tensor ``<1, 2, psi>`` of calibrated seed views and a novel view.

    The seed cameras are ``P1 = K [R1 | t1]`` and ``P2 = K [R2 | t2]`` (world to camera),
    all views sharing the intrinsics ``K``. The novel view is camera 2 moved by ``R`` and
    then ``t`` in camera 2's frame: a point at ``X2`` in camera 2's frame is at
    ``R X2 + t`` in the novel camera's, i.e. ``P_psi = K [R R2 | R t2 + t]``. In normalised
    coordinates and camera 1's frame the seed pair is ``[I | 0]``, ``[A | a]`` with
    ``A = R2 R1^T``, ``a = t2 - A t1`` (a Euclidean change of frame, which leaves the tensor
    unchanged); this builds :func:`seed_tensor` there, applies :func:`novel_view_tensor` and
    moves the result to pixels with :func:`transform_tensor` (``H = K`` in all three views).
    The result is proportional to ``trifocal_tensor(P1, P2, P_psi)``.

    Args:
        K: (3, 3) invertible intrinsics of all three views.
        R1: (3, 3) rotation of seed camera 1 (world to camera).
        t1: (3,) translation of seed camera 1.
        R2: (3, 3) rotation of seed camera 2.
        t2: (3,) translation of seed camera 2; camera 2's centre differs from camera 1's.
        R: (3, 3) rotation of the novel camera relative to camera 2.
        t: (3,) translation of the novel camera, in camera 2's frame after ``R``.
        dtype: floating dtype of the computation and the result.

    Returns:
        (3, 3, 3) tensor ``<1, 2, psi>`` for pixel coordinates, ready for
        :func:`~torch_eigview.geometry.transfer.transfer_points`.

    Raises:
        TypeError: an argument is not a floating tensor.
        ValueError: a shape is wrong, a value is not finite, a rotation is not one, ``K`` is
            singular, or the seed cameras are coincident.
    """
    k = _as_matrix(K, "K", (3, 3), dtype)
    s = torch.linalg.svdvals(k)
    if not bool(s[0] > 0) or float(s[2] / s[0]) <= _tol(K.dtype):
        raise ValueError(f"K must be invertible (3, 3) intrinsics, got singular values {s.tolist()}")
    r1 = _check_rotation(R1, "R1", dtype)
    v1 = _as_matrix(t1, "t1", (3,), dtype)
    r2 = _check_rotation(R2, "R2", dtype)
    v2 = _as_matrix(t2, "t2", (3,), dtype)
    r = _check_rotation(R, "R", dtype)
    v = _as_matrix(t, "t", (3,), dtype)
    a = r2 @ r1.T
    a4 = v2 - a @ v1
    scale = max(float(v1.norm()), float(v2.norm()), 1.0)
    if float(a4.norm()) <= 1e-12 * scale:
        raise ValueError("(R1, t1) and (R2, t2) are coincident seed cameras: their centres must differ")
    p1 = torch.eye(3, 4, dtype=dtype, device=a.device)
    p2 = torch.cat([a, a4[:, None]], dim=1)
    g = novel_view_tensor(_tensor(p1, p2, p2), a, r, v, dtype=dtype)
    return transform_tensor(g, k, k, k, dtype=dtype)
