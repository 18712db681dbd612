"""Point transfer through the trifocal tensor (Sec. 4), its epipoles and fundamental matrices."""

from __future__ import annotations

import pytest
import torch
from kornia.geometry.epipolar import fundamental_from_projections

from torch_eigview.geometry.transfer import epipoles_from_tensor, fundamental_from_tensor, transfer_points
from torch_eigview.geometry.trifocal import novel_view_tensor_from_cameras, seed_tensor, trifocal_tensor

from tests.geometry.cameras import (
    ALPHA,
    DT,
    LINES,
    THETAS,
    K,
    camera,
    homogeneous,
    pose,
    project,
    same_up_to_scale,
)


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
    le = homogeneous(p1) @ fundamental_from_projections(P1, P2).T
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
    a = torch.einsum("ni,ijk->njk", homogeneous(p1), alpha)
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
