"""The trifocal tensor (Sec. 4): HZ 17.12, the tensorial operator and point transfer."""

from __future__ import annotations

import math

import pytest
import torch
from kornia.geometry.epipolar import fundamental_from_projections, triangulate_points

from torch_eigview.geometry.trifocal import (
    epipoles_from_tensor,
    fundamental_from_tensor,
    novel_view_tensor,
    novel_view_tensor_from_cameras,
    seed_tensor,
    tensor_from_fundamental,
    transfer_points,
    transform_tensor,
    trifocal_tensor,
)

DT = torch.float64
ALPHA = 10.0
THETAS = [-20.0, 5.0, 25.0, 40.0]
LINES = ["perpendicular", "vertical", "paper"]
# 128x128 images, f = 0.45 * 128 * 4 as synthetic.PerspectiveCamera's default.
K = torch.tensor([[230.4, 0.0, 63.5], [0.0, 230.4, 63.5], [0.0, 0.0, 1.0]], dtype=DT)
DISTANCE = 4.0


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


def pose(phi: float) -> tuple[torch.Tensor, torch.Tensor]:
    """World to camera of a camera at DISTANCE on a horizontal circle, looking at the origin.

    The object turns by ``phi`` about Y (x = X cos + Z sin), then camera coordinates are
    (x, -y, DISTANCE - z): x right, y down, z forward.
    """
    c, s = math.cos(math.radians(phi)), math.sin(math.radians(phi))
    ry = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], dtype=DT)
    flip = torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=DT))
    return flip @ ry, torch.tensor([0.0, 0.0, DISTANCE], dtype=DT)


def camera(phi: float) -> torch.Tensor:
    r, t = pose(phi)
    return K @ torch.cat([r, t[:, None]], dim=1)


def project(P: torch.Tensor, X: torch.Tensor) -> torch.Tensor:
    x = _h(X) @ P.T
    return x[:, :2] / x[:, 2:]


def _h(p: torch.Tensor) -> torch.Tensor:
    return torch.cat([p, torch.ones_like(p[:, :1])], dim=1)


def skew(v: torch.Tensor) -> torch.Tensor:
    return torch.tensor([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]], dtype=DT)


def rotation(axis: list[float], degrees: float) -> torch.Tensor:
    n = torch.tensor(axis, dtype=DT)
    n = n / n.norm()
    w = skew(n)
    a = math.radians(degrees)
    return torch.eye(3, dtype=DT) + math.sin(a) * w + (1 - math.cos(a)) * w @ w


def same_up_to_scale(a: torch.Tensor, b: torch.Tensor) -> float:
    a, b = a / a.norm(), b / b.norm()
    return min(float((a - b).abs().max()), float((a + b).abs().max()))


@pytest.fixture(scope="module")
def points() -> torch.Tensor:
    """(40, 3) points in a unit cube, |Y| >= 0.2: away from the horizon row (degenerate for "paper")."""
    g = torch.Generator().manual_seed(0)
    X = 2 * torch.rand(40, 3, generator=g, dtype=DT) - 1
    X[:, 1] = torch.sign(X[:, 1]) * (0.2 + 0.8 * X[:, 1].abs())
    return X


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
    x1, x2, x3 = (_h(project(P, points)) for P in (P1, P2, P3))
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
    assert_incident(T122, _h(project(P1, points)), _h(project(P2, points)))


def test_epipoles_and_fundamental_from_tensor() -> None:
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(25.0)
    T = trifocal_tensor(P1, P2, P3)
    c1 = torch.cat([-torch.linalg.solve(P1[:, :3], P1[:, 3]), torch.ones(1, dtype=DT)])
    e2, e3 = epipoles_from_tensor(T)
    assert same_up_to_scale(e2, P2 @ c1) < 1e-9
    assert same_up_to_scale(e3, P3 @ c1) < 1e-9
    F21, F31 = fundamental_from_tensor(T)
    assert same_up_to_scale(F21, fundamental_from_projections(P1, P2)) < 1e-9
    assert same_up_to_scale(F31, fundamental_from_projections(P1, P3)) < 1e-9


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


@pytest.mark.parametrize("theta", THETAS)
@pytest.mark.parametrize("line", LINES)
def test_transfer_matches_projection(points: torch.Tensor, theta: float, line: str) -> None:
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(theta)
    p1, p2, p3 = (project(P, points) for P in (P1, P2, P3))
    T = trifocal_tensor(P1, P2, P3)
    got = transfer_points(T, p1, p2, line=line)
    assert got.shape == p1.shape and got.dtype == DT
    assert float((got - p3).abs().max()) < 1e-6
    # the same through the operator: novel pose relative to seed camera 2
    (r2, t2), (r3, t3) = pose(ALPHA), pose(theta)
    R = r3 @ r2.T
    G = novel_view_tensor_from_cameras(K, *pose(0.0), r2, t2, R, t3 - R @ t2)
    assert same_up_to_scale(G, T) < 1e-12
    assert float((transfer_points(G, p1, p2, line=line) - p3).abs().max()) < 1e-6


def test_perpendicular_line_ignores_error_across_the_epipolar_line(points: torch.Tensor) -> None:
    """HZ 16.7: the line is the perpendicular through p2, so moving p2 along the epipolar line's
    normal keeps the line and the transfer (it is that of p2's foot on the epipolar line)."""
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(25.0)
    p1, p2, p3 = (project(P, points) for P in (P1, P2, P3))
    le = _h(p1) @ fundamental_from_projections(P1, P2).T
    normal = le[:, :2] / le[:, :2].norm(dim=1, keepdim=True)
    got = transfer_points(trifocal_tensor(P1, P2, P3), p1, p2 + 3.0 * normal)
    assert float((got - p3).abs().max()) < 1e-6
    moved = transfer_points(trifocal_tensor(P1, P2, P3), p1, p2 + 3.0 * normal, line="vertical")
    assert float((moved - p3).abs().max()) > 0.1


def test_transfer_to_a_seed_view_gives_it_back(points: torch.Tensor) -> None:
    P1, P2 = camera(0.0), camera(ALPHA)
    p1, p2 = project(P1, points), project(P2, points)
    got = transfer_points(seed_tensor(P1, P2), p1, p2)
    assert float((got - p2).abs().max()) < 1e-6


def test_transfer_is_batched_and_accepts_f_and_float32(points: torch.Tensor) -> None:
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(25.0)
    p1, p2, p3 = (project(P, points) for P in (P1, P2, P3))
    T = trifocal_tensor(P1, P2, P3)
    got = transfer_points(T, torch.stack([p1, p1.flip(0)]), torch.stack([p2, p2.flip(0)]))
    assert got.shape == (2, len(points), 2)
    assert float((got[0] - p3).abs().max()) < 1e-6 and float((got[1] - p3.flip(0)).abs().max()) < 1e-6
    with_f = transfer_points(T, p1, p2, fundamental=fundamental_from_projections(P1, P2))
    assert float((with_f - p3).abs().max()) < 1e-6
    low = transfer_points(T.float(), p1.float(), p2.float())
    assert low.dtype == DT and float((low - p3).abs().max()) < 1e-3  # float32 inputs, float64 sums
    assert transfer_points(T, p1, p2, dtype=torch.float32).dtype == torch.float32


def test_paper_relations_as_printed_are_wrong(points: torch.Tensor) -> None:
    """The printed x'' is -x''; the printed y'' (vertical-line indices with y') is not y''."""
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(25.0)
    p1, p2, p3 = (project(P, points) for P in (P1, P2, P3))
    alpha = -trifocal_tensor(P1, P2, P3)  # Shashua's alpha_i^{jk}: j view 2, k view 3
    a = torch.einsum("ni,ijk->njk", _h(p1), alpha)
    x, y = p2[:, 0], p2[:, 1]
    printed_x = (x * a[:, 2, 0] - a[:, 0, 0]) / (a[:, 0, 2] - x * a[:, 2, 2])
    printed_y = (y * a[:, 2, 1] - a[:, 0, 1]) / (a[:, 0, 2] - y * a[:, 2, 2])
    assert torch.allclose(printed_x, -p3[:, 0], atol=1e-6)
    assert float((printed_y - p3[:, 1]).abs().min()) > 1e-2
    paper = transfer_points(-alpha, p1, p2, line="paper")
    assert torch.allclose(paper, p3, atol=1e-6)


def test_paper_line_is_nan_on_the_horizon_row() -> None:
    """Points with Y = 0 image on row 63.5 in every view: there the horizontal line through p2
    is the epipolar line of p1, so "paper"'s y'' is 0/0 (NaN); its x'' and the other lines work."""
    g = torch.Generator().manual_seed(4)
    X = 2 * torch.rand(6, 3, generator=g, dtype=DT) - 1
    X[:, 1] = 0.0
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(25.0)
    p1, p2, p3 = (project(P, X) for P in (P1, P2, P3))
    T = trifocal_tensor(P1, P2, P3)
    paper = transfer_points(T, p1, p2, line="paper")
    assert bool(paper[:, 1].isnan().all())
    assert float((paper[:, 0] - p3[:, 0]).abs().max()) < 1e-6
    for line in ("perpendicular", "vertical"):
        assert float((transfer_points(T, p1, p2, line=line) - p3).abs().max()) < 1e-6


def test_perpendicular_line_is_nan_at_the_epipole() -> None:
    """p1 at the epipole of camera 2 has no epipolar line, so no perpendicular to it."""
    P1, P2, P3 = camera(0.0), camera(ALPHA), camera(25.0)
    c2 = torch.cat([-torch.linalg.solve(P2[:, :3], P2[:, 3]), torch.ones(1, dtype=DT)])
    e12 = P1 @ c2
    p1 = torch.stack([e12[:2] / e12[2], torch.tensor([30.0, 40.0], dtype=DT)])
    p2 = torch.tensor([[10.0, 20.0], [31.0, 41.0]], dtype=DT)
    got = transfer_points(trifocal_tensor(P1, P2, P3), p1, p2)
    assert bool(got[0].isnan().all()) and bool(got[1].isfinite().all())


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
    assert_incident(T122, _h(p1), _h(p2))
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


def test_bad_transfer_input() -> None:
    T = trifocal_tensor(camera(0.0), camera(ALPHA), camera(25.0))
    p = torch.zeros(4, 2, dtype=DT)
    with pytest.raises(ValueError, match="line must be one of"):
        transfer_points(T, p, p, line="horizontal")
    with pytest.raises(TypeError, match="line must be a string"):
        transfer_points(T, p, p, line=1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="p2 must have the shape of p1"):
        transfer_points(T, p, p[:3])
    with pytest.raises(ValueError, match=r"p1 must have shape \(\.\.\., N, 2\)"):
        transfer_points(T, torch.zeros(4, 3, dtype=DT), torch.zeros(4, 3, dtype=DT))
    with pytest.raises(TypeError, match=r"p1 must be a torch\.Tensor"):
        transfer_points(T, [[0.0, 0.0]], p[:1])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"fundamental must have shape \(3, 3\)"):
        transfer_points(T, p, p, fundamental=torch.zeros(3, 4, dtype=DT))
