"""The trifocal tensor (Sec. 4): HZ 17.12, the tensorial operator, the uncalibrated seed pair."""

from __future__ import annotations

import math

import pytest
import torch
from kornia.geometry.epipolar import fundamental_from_projections, triangulate_points

from torch_eigview.geometry.transfer import fundamental_from_tensor, transfer_points
from torch_eigview.geometry.trifocal import (
    novel_view_tensor,
    novel_view_tensor_from_cameras,
    seed_tensor,
    tensor_from_fundamental,
    transform_tensor,
    trifocal_tensor,
)

from tests.geometry.cameras import (
    ALPHA,
    DT,
    THETAS,
    K,
    camera,
    homogeneous,
    pose,
    project,
    rotation,
    same_up_to_scale,
    skew,
)


def reference_tensor(P1: torch.Tensor, P2: torch.Tensor, P3: torch.Tensor) -> torch.Tensor:
    """HZ 17.12 one determinant at a time."""
    T = torch.zeros(3, 3, 3, dtype=DT)
    for i in range(3):
        rest = torch.cat([P1[:i], P1[i + 1 :]])
        for q in range(3):
            for r in range(3):
                m = torch.cat([rest, P2[q : q + 1], P3[r : r + 1]])
                T[i, q, r] = (-1) ** i * torch.linalg.det(m)
    return T


def random_camera(g: torch.Generator) -> torch.Tensor:
    return torch.randn(3, 4, generator=g, dtype=DT)


# --- the tensor ----------------------------------------------------------------------------


def test_tensor_matches_loop_reference_for_general_cameras() -> None:
    g = torch.Generator().manual_seed(1)
    for _ in range(3):
        P1, P2, P3 = (random_camera(g) for _ in range(3))
        T = trifocal_tensor(P1, P2, P3)
        ref = reference_tensor(P1, P2, P3)
        assert T.shape == (3, 3, 3) and T.dtype == DT
        assert torch.allclose(T, ref, rtol=0, atol=1e-12 * float(ref.abs().max()))


def test_canonical_cameras_give_hz_closed_form() -> None:
    g = torch.Generator().manual_seed(2)
    A, B = torch.randn(3, 3, generator=g, dtype=DT), torch.randn(3, 3, generator=g, dtype=DT)
    a, b = torch.randn(3, generator=g, dtype=DT), torch.randn(3, generator=g, dtype=DT)
    P1 = torch.eye(3, 4, dtype=DT)
    T = trifocal_tensor(P1, torch.cat([A, a[:, None]], 1), torch.cat([B, b[:, None]], 1))
    for i in range(3):
        for j in range(3):
            for k in range(3):
                assert float(T[i, j, k]) == pytest.approx(float(A[j, i] * b[k] - a[j] * B[k, i]), abs=1e-12)


@pytest.mark.parametrize("theta", THETAS)
def test_point_point_point_incidence(points: torch.Tensor, theta: float) -> None:
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(theta)
    T = trifocal_tensor(P1, P2, P3)
    x1, x2, x3 = (homogeneous(project(P, points)) for P in (P1, P2, P3))
    for n in range(len(points)):
        m = skew(x2[n]) @ torch.einsum("i,ijk->jk", x1[n], T) @ skew(x3[n])
        scale = float(T.norm() * x1[n].norm() * x2[n].norm() * x3[n].norm())
        assert float(m.abs().max()) < 1e-10 * scale
    # a wrong match breaks it: the check is not vacuous
    m = skew(x2[0]) @ torch.einsum("i,ijk->jk", x1[0], T) @ skew(x3[1])
    assert float(m.abs().max()) > 1e-4 * float(T.norm() * x1[0].norm() * x2[0].norm() * x3[1].norm())


def assert_incident(T: torch.Tensor, x1: torch.Tensor, x2: torch.Tensor) -> None:
    """<1, 2, 2>: [x2]_x (sum_i x1^i T_i) [x2]_x = 0 (every line through x2 transfers x1 to x2)."""
    for n in range(len(x1)):
        m = skew(x2[n]) @ torch.einsum("i,ijk->jk", x1[n], T) @ skew(x2[n])
        assert float(m.abs().max()) < 1e-10 * float(T.norm() * x1[n].norm() * x2[n].norm() ** 2)


def test_seed_tensor_is_antisymmetric_and_incident(points: torch.Tensor) -> None:
    P1, P2 = camera(0.0), camera(ALPHA)
    T122 = seed_tensor(P1, P2)
    assert torch.equal(T122, trifocal_tensor(P1, P2, P2))
    assert float((T122 + T122.transpose(1, 2)).abs().max()) < 1e-12 * float(T122.abs().max())
    assert_incident(T122, homogeneous(project(P1, points)), homogeneous(project(P2, points)))


def test_transform_tensor_is_the_pixel_tensor() -> None:
    rs, ts = zip(*(pose(phi) for phi in (0.0, ALPHA, 25.0)), strict=True)
    normalised = [torch.cat([r, t[:, None]], 1) for r, t in zip(rs, ts, strict=True)]
    pixel = transform_tensor(trifocal_tensor(*normalised), K, K, K)
    assert same_up_to_scale(pixel, trifocal_tensor(*(K @ p for p in normalised))) < 1e-12


# --- the tensorial operator ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("axis", "degrees", "t"),
    [
        ([0, 1, 0], 0.0, [0.0, 0.0, 0.0]),
        ([0, 1, 0], 15.0, [0.5, 0.0, 0.1]),
        ([1, 2, -1], -30.0, [-1.0, 0.3, 2.0]),
    ],
)
def test_novel_view_tensor_equals_tensor_of_moved_camera(
    axis: list[float], degrees: float, t: list[float]
) -> None:
    g = torch.Generator().manual_seed(3)
    A, a = torch.randn(3, 3, generator=g, dtype=DT), torch.randn(3, generator=g, dtype=DT)
    R, tt = rotation(axis, degrees), torch.tensor(t, dtype=DT)
    P1, P2 = torch.eye(3, 4, dtype=DT), torch.cat([A, a[:, None]], 1)
    Ppsi = torch.cat([R @ A, (R @ a + tt)[:, None]], 1)
    G = novel_view_tensor(seed_tensor(P1, P2), A, R, tt)
    expected = trifocal_tensor(P1, P2, Ppsi)
    assert same_up_to_scale(G, expected) < 1e-12
    assert torch.allclose(
        G, expected, rtol=0, atol=1e-12 * float(expected.abs().max())
    )  # the very same scale


# --- uncalibrated seed pair ----------------------------------------------------------------


def test_tensor_from_fundamental(points: torch.Tensor) -> None:
    P1, P2 = camera(0.0), camera(ALPHA)
    F = fundamental_from_projections(P1, P2)
    T122, A, e2 = tensor_from_fundamental(F)
    assert float((F.T @ e2).abs().max()) < 1e-9 * float(F.abs().max())
    assert torch.allclose(A, skew(e2) @ F)
    frame2 = torch.cat([A, e2[:, None]], 1)
    ref = reference_tensor(torch.eye(3, 4, dtype=DT), frame2, frame2)
    assert torch.allclose(T122, ref, rtol=0, atol=1e-12 * float(ref.abs().max()))
    p1, p2 = project(P1, points), project(P2, points)
    assert_incident(T122, homogeneous(p1), homogeneous(p2))
    assert same_up_to_scale(fundamental_from_tensor(T122)[0], F) < 1e-9
    # the operator in the projective frame it fixes: transfer = projection of the triangulated points
    R, t = rotation([0, 1, 0], 12.0), torch.tensor([0.3, -0.1, 0.2], dtype=DT)
    G = novel_view_tensor(T122, A, R, t)
    X = triangulate_points(
        torch.eye(3, 4, dtype=DT), frame2, p1, p2, solver="svd"
    )  # "eigh" loses this badly scaled frame
    expected = project(torch.cat([R @ A, (R @ e2 + t)[:, None]], 1), X)
    assert float((transfer_points(G, p1, p2) - expected).abs().max()) < 1e-6


# --- bad input -----------------------------------------------------------------------------


def test_bad_cameras() -> None:
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(25.0)
    rank2 = P3.clone()
    rank2[2] = P3[0] + P3[1]
    with pytest.raises(ValueError, match="P3 is a singular camera"):
        trifocal_tensor(P1, P2, rank2)
    at_infinity = P2.clone()
    at_infinity[2, :3] = 0.0
    with pytest.raises(ValueError, match="P2 is a singular camera"):
        trifocal_tensor(P1, at_infinity, P3)
    with pytest.raises(ValueError, match="coincident seed cameras"):
        trifocal_tensor(P1, 2.0 * K @ rotation([0, 1, 0], 5.0) @ torch.linalg.solve(K, P1), P3)
    with pytest.raises(ValueError, match=r"P1 must have shape \(3, 4\)"):
        trifocal_tensor(P1[:, :3], P2, P3)
    with pytest.raises(TypeError, match=r"P2 must be a torch\.Tensor"):
        trifocal_tensor(P1, P2.tolist(), P3)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="P3 must have a floating dtype"):
        trifocal_tensor(P1, P2, P3.long())
    nan = P1.clone()
    nan[0, 0] = math.nan
    with pytest.raises(ValueError, match="P1 must be finite"):
        seed_tensor(nan, P2)


def test_bad_operator_input() -> None:
    T122, A = seed_tensor(camera(0.0), camera(ALPHA)), torch.eye(3, dtype=DT)
    t = torch.zeros(3, dtype=DT)
    with pytest.raises(ValueError, match="R must be a rotation"):
        novel_view_tensor(T122, A, 1.1 * torch.eye(3, dtype=DT), t)
    with pytest.raises(ValueError, match="R must be a rotation"):
        novel_view_tensor(T122, A, torch.diag(torch.tensor([1.0, 1.0, -1.0], dtype=DT)), t)
    with pytest.raises(ValueError, match=r"t must have shape \(3,\)"):
        novel_view_tensor(T122, A, torch.eye(3, dtype=DT), t[:2])
    with pytest.raises(ValueError, match=r"T122 must have shape \(3, 3, 3\)"):
        novel_view_tensor(T122[0], A, torch.eye(3, dtype=DT), t)
    r1, t1 = pose(0.0)
    with pytest.raises(ValueError, match="coincident seed cameras"):
        novel_view_tensor_from_cameras(K, r1, t1, r1, t1, torch.eye(3, dtype=DT), t)
    with pytest.raises(ValueError, match="R2 must be a rotation"):
        novel_view_tensor_from_cameras(K, r1, t1, 2 * r1, t1, torch.eye(3, dtype=DT), t)
    with pytest.raises(ValueError, match="K must be invertible"):
        novel_view_tensor_from_cameras(
            torch.zeros(3, 3, dtype=DT), r1, t1, *pose(ALPHA), torch.eye(3, dtype=DT), t
        )
    with pytest.raises(ValueError, match="F must be a fundamental matrix of rank 2"):
        tensor_from_fundamental(torch.outer(torch.ones(3, dtype=DT), torch.arange(3, dtype=DT)))
    with pytest.raises(ValueError, match="H1 must be an invertible"):
        transform_tensor(T122, torch.zeros(3, 3, dtype=DT), K, K)
