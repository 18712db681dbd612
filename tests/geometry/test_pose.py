"""Camera model: Eq. 7's coefficients against the projection geometry, and the elevation fit."""

from __future__ import annotations

import math

import pytest
import torch

from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.pose import (
    affine_coefficients,
    estimate_elevation,
    orthographic_coefficients,
    rotation_y,
)

ALPHAS = [20.0, -35.0, 5.0, 120.0]


def _project(big_x: torch.Tensor, big_z: torch.Tensor, phi_deg: float, c: float) -> torch.Tensor:
    """Orthographic camera at angle phi rotating about the vertical axis: x = c + X cos + Z sin."""
    phi = math.radians(phi_deg)
    return c + big_x * math.cos(phi) + big_z * math.sin(phi)


def _points(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    gen = torch.Generator().manual_seed(seed)
    pts = (torch.rand(2, n, generator=gen, dtype=torch.float64) - 0.5) * 100
    return pts[0], pts[1]


# --- Eq. 7 ------------------------------------------------------------------------------


@pytest.mark.parametrize("alpha", ALPHAS)
def test_seed_angles_give_the_seed_views(alpha: float) -> None:
    a, b = orthographic_coefficients([0.0, alpha], alpha)
    torch.testing.assert_close(a, torch.tensor([1.0, 0.0], dtype=torch.float64), atol=1e-15, rtol=0)
    torch.testing.assert_close(b, torch.tensor([0.0, 1.0], dtype=torch.float64), atol=1e-15, rtol=0)


@pytest.mark.parametrize("alpha", ALPHAS)
def test_known_values(alpha: float) -> None:
    # Half-way between the seed views both weigh the same, 1 / (2 cos(alpha / 2)); at
    # theta = alpha + 90 degrees b = cos(alpha) / sin(alpha) and a = -1 / sin(alpha).
    half = math.radians(alpha / 2)
    a, b = orthographic_coefficients([alpha / 2, alpha + 90.0], alpha)
    s, co = math.sin(math.radians(alpha)), math.cos(math.radians(alpha))
    torch.testing.assert_close(a, torch.tensor([1 / (2 * math.cos(half)), -1 / s], dtype=torch.float64))
    torch.testing.assert_close(b, torch.tensor([1 / (2 * math.cos(half)), co / s], dtype=torch.float64))


def test_numeric_case() -> None:
    # alpha = 30, theta = 45: a = sin(-15°) / sin(30°) = -2 sin(15°), b = sin(45°) / sin(30°) = √2.
    a, b = orthographic_coefficients(45.0, alpha=30.0)
    assert a.shape == b.shape == (1,)
    assert abs(float(a) - (-(math.sqrt(6) - math.sqrt(2)) / 2)) < 1e-14
    assert abs(float(b) - math.sqrt(2)) < 1e-14


@pytest.mark.parametrize("alpha", ALPHAS)
@pytest.mark.parametrize("c", [0.0, 31.5])
def test_eq2_holds_for_projected_points(alpha: float, c: float) -> None:
    """x3 - c = a (x1 - c) + b (x2 - c) for any 3D point, inside and outside [0, alpha]."""
    big_x, big_z = _points(500, seed=1)
    thetas = torch.linspace(-90.0, 200.0, 59, dtype=torch.float64)  # step 5°, with extrapolation
    a, b = orthographic_coefficients(thetas, alpha)
    x1, x2 = _project(big_x, big_z, 0.0, c), _project(big_x, big_z, alpha, c)
    for theta, ai, bi in zip(thetas.tolist(), a, b, strict=True):
        x3 = _project(big_x, big_z, theta, c)
        torch.testing.assert_close(c + ai * (x1 - c) + bi * (x2 - c), x3, atol=1e-12, rtol=0)


def test_output_shapes_and_dtype() -> None:
    for thetas, n in [(3.0, 1), (7, 1), ([1.0, 2.0, 3.0], 3), ((0.0, 4.0), 2), (torch.arange(6.0), 6)]:
        a, b = orthographic_coefficients(thetas, 10.0)
        assert a.shape == b.shape == (n,)
        assert a.dtype == b.dtype == torch.float64
    a, b = orthographic_coefficients(torch.arange(4.0, dtype=torch.float64), 10.0, dtype=torch.float32)
    assert a.dtype == b.dtype == torch.float32
    ref = orthographic_coefficients(torch.arange(4.0, dtype=torch.float64), 10.0)
    torch.testing.assert_close(a, ref[0].float())
    # A float32 angle is widened before the trigonometry, not after.
    a32, _ = orthographic_coefficients(torch.tensor([7.3], dtype=torch.float32), 10.0)
    a64, _ = orthographic_coefficients([float(torch.tensor(7.3, dtype=torch.float32))], 10.0)
    assert torch.equal(a32, a64)


@pytest.mark.parametrize(
    ("alpha", "error", "match"),
    [
        (0.0, ValueError, r"alpha=0\.0 must not be a multiple of 180"),
        (180, ValueError, r"alpha=180\.0 must not be a multiple of 180"),
        (-360.0, ValueError, r"alpha=-360\.0 must not be a multiple of 180"),
        (float("nan"), ValueError, r"alpha=nan must be finite"),
        (float("inf"), ValueError, r"alpha=inf must be finite"),
        (True, TypeError, r"alpha must be a number of degrees, got bool"),
        ("5", TypeError, r"alpha must be a number of degrees, got str"),
        (None, TypeError, r"alpha must be a number of degrees, got NoneType"),
    ],
)
def test_bad_alpha(alpha: object, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        orthographic_coefficients([1.0], alpha)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("thetas", "error", "match"),
    [
        ([], ValueError, r"thetas must hold at least one angle"),
        (torch.zeros(0), ValueError, r"thetas must hold at least one angle"),
        ([1.0, float("nan")], ValueError, r"thetas must be finite, got 1 NaN"),
        (torch.tensor([float("inf")]), ValueError, r"thetas must be finite"),
        ("10", TypeError, r"thetas must be a number, a sequence of numbers or a tensor, got str"),
        (None, TypeError, r"thetas must be a number"),
        ([1.0, "x"], TypeError, r"thetas must hold numbers"),
    ],
)
def test_bad_thetas(thetas: object, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        orthographic_coefficients(thetas, 10.0)


def test_thetas_must_be_one_dimensional() -> None:
    with pytest.raises(ValueError, match="thetas"):
        orthographic_coefficients(torch.zeros(2, 3), 10.0)


def test_bool_theta_is_a_type_error() -> None:
    with pytest.raises(TypeError, match="thetas"):
        orthographic_coefficients([True], 10.0)


# --- elevation --------------------------------------------------------------------------


def _tilted_correspondence(
    elevations: list[float], alpha: float, h: int = 6, w: int = 11, c: float | None = None, seed: int = 0
) -> Correspondence:
    """Exact correspondences of random-depth points seen by a camera tilted by ``elevation``.

    A view-1 pixel in column x1 is the point X = x1 - c at a random depth Z; view 2 sees it
    at x2 = c + X cos(alpha) + Z sin(alpha), and its row moves by
    y2 - y1 = -sin(elevation) (Z (cos(alpha) - 1) - X sin(alpha)).
    """
    b = len(elevations)
    c = (w - 1) / 2 if c is None else c
    gen = torch.Generator().manual_seed(seed)
    big_z = (torch.rand(b, h, w, generator=gen, dtype=torch.float64) - 0.5) * 2 * w
    big_x = (torch.arange(w, dtype=torch.float64) - c).expand(b, h, w)
    al = math.radians(alpha)
    x2 = c + big_x * math.cos(al) + big_z * math.sin(al)
    d12 = x2 - (big_x + c)
    tilt = torch.sin(torch.deg2rad(torch.tensor(elevations, dtype=torch.float64))).view(b, 1, 1)
    dy = -tilt * (big_z * (math.cos(al) - 1) - big_x * math.sin(al))
    ones = torch.ones(b, h, w, dtype=torch.bool)
    return Correspondence(d12, -d12, ones, ones, dy)


@pytest.mark.parametrize("alpha", [20.0, -35.0, 72.0])
def test_elevation_recovered(alpha: float) -> None:
    elevations = [12.5, -7.0, 0.0, 40.0]
    corr = _tilted_correspondence(elevations, alpha)
    est = estimate_elevation(corr, alpha)
    assert est.shape == (4,) and est.dtype == torch.float64
    torch.testing.assert_close(est, torch.tensor(elevations, dtype=torch.float64), atol=1e-6, rtol=0)


def test_elevation_center_and_dtype() -> None:
    corr = _tilted_correspondence([25.0], 15.0, w=16, c=4.0)
    torch.testing.assert_close(
        estimate_elevation(corr, 15.0, center=4.0), torch.tensor([25.0], dtype=torch.float64)
    )
    # float32 correspondences give a float32 elevation, still accurate.
    est = estimate_elevation(corr.to(dtype=torch.float32), 15.0, center=4.0)
    assert est.dtype == torch.float32
    assert abs(float(est) - 25.0) < 1e-3


def test_elevation_uses_only_trusted_and_masked_pixels() -> None:
    corr = _tilted_correspondence([10.0, -20.0], 30.0, h=8, w=12)
    gen = torch.Generator().manual_seed(5)
    junk = torch.rand(corr.shape, generator=gen) < 0.3
    untrusted = torch.rand(corr.shape, generator=gen) < 0.3
    bad_dy = torch.where(junk | untrusted, 100.0 * torch.ones_like(corr.vertical_12), corr.vertical_12)
    corr = Correspondence(corr.disparity_12, corr.disparity_21, ~untrusted, corr.valid_21, bad_dy)
    est = estimate_elevation(corr, 30.0, mask=~junk)
    torch.testing.assert_close(est, torch.tensor([10.0, -20.0], dtype=torch.float64))


def test_elevation_errors() -> None:
    corr = _tilted_correspondence([10.0], 20.0)
    no_flow = Correspondence(corr.disparity_12, corr.disparity_21, corr.valid_12, corr.valid_21)
    with pytest.raises(ValueError, match=r"vertical_12 is None"):
        estimate_elevation(no_flow, 20.0)
    with pytest.raises(ValueError, match=r"alpha=0\.0 must not be a multiple of 180"):
        estimate_elevation(corr, 0.0)
    with pytest.raises(ValueError, match=r"no trusted correspondence"):
        estimate_elevation(corr, 20.0, mask=torch.zeros(corr.shape, dtype=torch.bool))


# --- Sec. 4: the affine camera --------------------------------------------------------
def _affine_project(cam: torch.Tensor, pts: torch.Tensor, phi_deg: float) -> torch.Tensor:
    """(N, 2) image points of object points (N, 3) turned by phi: M R(phi) X + t."""
    r = rotation_y(torch.tensor(math.radians(phi_deg), dtype=torch.float64))
    return pts @ r.T @ cam[:, :3].T + cam[:, 3]


@pytest.mark.parametrize("alpha", ALPHAS)
@pytest.mark.parametrize("scale", [1.0, 37.5])
def test_affine_reduces_to_eq7_for_orthographic(alpha: float, scale: float) -> None:
    cam = torch.tensor([[scale, 0.0, 0.0, 31.5], [0.0, -scale, 0.0, 40.0]], dtype=torch.float64)
    thetas = [-40.0, 0.0, alpha / 3, alpha, alpha + 25.0]
    coef = affine_coefficients(cam, alpha, thetas)
    a, b = orthographic_coefficients(thetas, alpha)
    torch.testing.assert_close(coef.a, a, rtol=0, atol=1e-12)
    torch.testing.assert_close(coef.b, b, rtol=0, atol=1e-12)
    assert coef.center == 31.5 and float(coef.residual.max()) < 1e-12


@pytest.mark.parametrize(
    "matrix", [((40.0, 0.0, 20.0), (0.0, -55.0, 0.0)), ((-30.0, 0.0, 45.0), (0.0, 25.0, 0.0))]
)
def test_affine_eq2_holds_for_projected_points(matrix: tuple[tuple[float, ...], ...]) -> None:
    """A general affine camera whose x does not see the height: Eq. 2 holds for any point."""
    cam = torch.cat([torch.tensor(matrix, dtype=torch.float64), torch.tensor([[12.0], [-3.0]])], dim=1)
    pts = torch.randn(50, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    alpha, thetas = 12.0, [-30.0, 5.0, 20.0, 70.0]
    coef = affine_coefficients(cam, alpha, thetas)
    x1, x2 = _affine_project(cam, pts, 0.0), _affine_project(cam, pts, alpha)
    for i, theta in enumerate(thetas):
        x3 = _affine_project(cam, pts, theta)
        pred = coef.center + coef.a[i] * (x1[:, 0] - coef.center) + coef.b[i] * (x2[:, 0] - coef.center)
        torch.testing.assert_close(pred, x3[:, 0], rtol=0, atol=1e-10)
        torch.testing.assert_close(x3[:, 1], x1[:, 1], rtol=0, atol=1e-10)  # rows stay rows
    # A (3, 4) affine camera with last row (0, 0, 0, 1) is the same camera.
    cam34 = torch.cat([cam, torch.tensor([[0.0, 0.0, 0.0, 1.0]], dtype=torch.float64)])
    torch.testing.assert_close(affine_coefficients(cam34, alpha, thetas).a, coef.a)


def test_affine_residual_is_an_error_where_eq2_cannot_hold() -> None:
    # x depends on the height Y: m R(theta) keeps M[0, 1], a m + b m R(alpha) scales it by a + b.
    cam = torch.tensor([[40.0, 8.0, 0.0, 0.0], [0.0, -40.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"Eq\. 2 cannot hold.*residual.*depends on the height"):
        affine_coefficients(cam, 10.0, [5.0, 20.0])
    coef = affine_coefficients(cam, 10.0, [5.0, 20.0], tol=math.inf)  # reported, not raised
    assert float(coef.residual.min()) > 1e-4
    # A tilted camera: y moves with the rotation, rows do not stay rows.
    tilt = torch.tensor([[40.0, 0.0, 0.0], [0.0, -38.0, 12.0]])
    with pytest.raises(ValueError, match=r"rows do not stay rows"):
        affine_coefficients(tilt, 10.0, [5.0])
    # The warp refuses such cameras when it is built, not only when it warps.
    from torch_eigview.warp.novel_view import NovelViewWarp

    with pytest.raises(ValueError, match=r"depends on the height"):
        NovelViewWarp(10.0, camera=cam)
    with pytest.raises(ValueError, match=r"rows do not stay rows"):
        NovelViewWarp(10.0, camera=tilt)
    # Rows must stay rows between the seeds too, whatever the novel angle.
    with pytest.raises(ValueError, match=r"rows do not stay rows"):
        affine_coefficients(tilt, 10.0, [0.0])
    # At the seed angles the x system holds whatever the camera: only y's motion remains.
    assert float(affine_coefficients(cam, 10.0, [0.0, 10.0], tol=math.inf).residual.max()) < 1e-12


def test_affine_bad_input() -> None:
    good = torch.tensor([[40.0, 0.0, 0.0], [0.0, -40.0, 0.0]])
    with pytest.raises(ValueError, match=r"camera is singular.*rank 2"):
        affine_coefficients(torch.tensor([[40.0, 0.0, 0.0], [20.0, 0.0, 0.0]]), 10.0, [5.0])
    with pytest.raises(ValueError, match=r"camera's first row .* horizontal part"):
        affine_coefficients(torch.tensor([[0.0, 40.0, 0.0], [0.0, 0.0, 40.0]]), 10.0, [5.0])
    with pytest.raises(ValueError, match=r"alpha=180.0 must not be a multiple of 180"):
        affine_coefficients(good, 180.0, [5.0])  # coincident seed cameras
    with pytest.raises(ValueError, match=r"camera must have shape \(2, 3\), \(2, 4\) or \(3, 4\)"):
        affine_coefficients(torch.zeros(3, 3), 10.0, [5.0])
    with pytest.raises(ValueError, match=r"camera of shape \(3, 4\) must be affine"):
        affine_coefficients(torch.eye(3, 4), 10.0, [5.0])
    with pytest.raises(ValueError, match=r"camera must be finite"):
        affine_coefficients(torch.full((2, 3), math.nan), 10.0, [5.0])
    with pytest.raises(TypeError, match=r"camera must be a torch\.Tensor"):
        affine_coefficients([[1.0, 0, 0], [0, 1.0, 0]], 10.0, [5.0])  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"camera must have a floating dtype"):
        affine_coefficients(torch.ones(2, 3, dtype=torch.int64), 10.0, [5.0])
    with pytest.raises(ValueError, match=r"thetas must hold at least one angle"):
        affine_coefficients(good, 10.0, [])
