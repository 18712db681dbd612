"""PerspectiveWarp (Sec. 4): trifocal transfer + 2D warp against the renderer's ground truth."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from torch_eigview.datasets import PerspectiveCamera, exact_correspondence_2d, make_object, render
from torch_eigview.geometry.correspondence import correspondence_from_disparity
from torch_eigview.warp.novel_view import NovelViewWarp
from torch_eigview.warp.operator import SparseViewOperator
from torch_eigview.warp.perspective import PerspectiveWarp, turntable_pose

from tests.helpers import warp_errors

SIZE = 64
ALPHA = 10.0
THETAS = [-15.0, -5.0, 4.0, 15.0]


@pytest.fixture(scope="module")
def camera() -> PerspectiveCamera:
    return PerspectiveCamera(SIZE, distance=4.0)


@pytest.fixture(scope="module", params=["head", "superquadric"])
def scene(request: pytest.FixtureRequest, camera: PerspectiveCamera) -> tuple[object, torch.Tensor, object]:
    obj = make_object(request.param, seed=3)
    seeds = torch.stack([render(obj, 0.0, camera).image, render(obj, ALPHA, camera).image])
    return obj, seeds, exact_correspondence_2d(obj, ALPHA, camera)


def test_turntable_pose_is_the_renderers_camera(camera: PerspectiveCamera) -> None:
    points = torch.randn(20, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64) * 0.5
    for theta in (0.0, 17.0, -40.0):
        r, t = turntable_pose(theta, camera.distance)
        q = (points @ r.T + t) @ camera._k.T
        pc = (
            points
            @ torch.tensor(  # the renderer: object turned by theta, then projected
                [
                    [math.cos(math.radians(theta)), 0, math.sin(math.radians(theta))],
                    [0, 1, 0],
                    [-math.sin(math.radians(theta)), 0, math.cos(math.radians(theta))],
                ],
                dtype=torch.float64,
            ).T
        )
        x, y, _ = camera.project(pc)
        torch.testing.assert_close(q[:, 0] / q[:, 2], x, rtol=0, atol=1e-9)
        torch.testing.assert_close(q[:, 1] / q[:, 2], y, rtol=0, atol=1e-9)


def test_warp_with_exact_correspondences_matches_render(scene: tuple, camera: PerspectiveCamera) -> None:
    obj, _, corr = scene
    warp = PerspectiveWarp(ALPHA, camera._k, camera.distance)
    errors = warp_errors(ALPHA, THETAS, obj, camera, corr, warp)
    print(
        f"perspective, exact correspondences, mean abs error per angle {THETAS}: {[f'{e:.4f}' for e in errors]}"
    )
    # The paper: under 1% per pixel. Measured 0.13-0.7% (the largest at -15 deg).
    assert max(errors) < 0.01


def test_seed_views_are_reproduced(scene: tuple, camera: PerspectiveCamera) -> None:
    _, seeds, corr = scene
    views = PerspectiveWarp(ALPHA, camera._k, camera.distance)(
        seeds[0], seeds[1], correspondence=corr, thetas=[0.0, ALPHA]
    )
    torch.testing.assert_close(views[0], seeds[0], rtol=0, atol=1e-5)
    # At alpha, source 2 is the identity wherever it sees the pixel, which is everywhere.
    torch.testing.assert_close(views[1], seeds[1], rtol=0, atol=1e-5)


@pytest.mark.slow
def test_sparse_operator_gives_the_warped_views(scene: tuple, camera: PerspectiveCamera) -> None:
    """Sec. 4: G·C with whole-image coefficient vectors equals the kornia 2D warp."""
    _, seeds, corr = scene
    warp = PerspectiveWarp(ALPHA, camera._k, camera.distance)
    maps = warp.maps(corr, THETAS)
    assert maps.src_y is not None
    expected = warp.apply_maps(maps, seeds[:, None])[0]
    op = SparseViewOperator.from_maps(seeds, maps)
    assert op.layout == "image"
    assert float((op.views() - expected).abs().max()) < 1e-5


def test_differentiable_and_batched(scene: tuple, camera: PerspectiveCamera) -> None:
    _, seeds, corr = scene
    warp = PerspectiveWarp(ALPHA, camera._k, camera.distance)
    v1 = seeds[0].clone().requires_grad_(True)
    warp(v1, seeds[1], correspondence=corr, thetas=[5.0]).sum().backward()
    assert v1.grad is not None and float(v1.grad.abs().sum()) > 0
    batch = dataclasses.replace(
        corr, **{f.name: torch.cat([getattr(corr, f.name)] * 2) for f in dataclasses.fields(corr)}
    )
    two = warp(
        seeds[0].expand(2, -1, -1, -1), seeds[1].expand(2, -1, -1, -1), correspondence=batch, thetas=[5.0]
    )
    one = warp(seeds[0], seeds[1], correspondence=corr, thetas=[5.0])
    torch.testing.assert_close(two[1], one, rtol=0, atol=1e-6)


def test_bad_input(camera: PerspectiveCamera) -> None:
    k = camera._k
    with pytest.raises(ValueError, match=r"K must be invertible"):
        PerspectiveWarp(ALPHA, torch.zeros(3, 3), 4.0)
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\)"):
        PerspectiveWarp(ALPHA, torch.eye(4), 4.0)
    with pytest.raises(TypeError, match=r"K must be a \(3, 3\) torch\.Tensor"):
        PerspectiveWarp(ALPHA, [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], 4.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"distance=0.0 must be a positive"):
        PerspectiveWarp(ALPHA, k, 0.0)
    with pytest.raises(ValueError, match=r"alpha=0.0 must not be a multiple of 180"):
        PerspectiveWarp(0.0, k, 4.0)  # coincident seed cameras
    with pytest.raises(ValueError, match=r"line must be"):
        PerspectiveWarp(ALPHA, k, 4.0, line="diagonal")
    flat = correspondence_from_disparity(torch.zeros(SIZE, SIZE))
    with pytest.raises(ValueError, match=r"correspondence must be 2D for a perspective camera"):
        PerspectiveWarp(ALPHA, k, 4.0).maps(flat, [5.0])
    with pytest.raises(ValueError, match=r"grow=-1 must be >= 0"):
        PerspectiveWarp(ALPHA, k, 4.0, grow=-1)
    with pytest.raises(TypeError, match=r"grow must be an integer"):
        PerspectiveWarp(ALPHA, k, 4.0, grow=1.5)  # type: ignore[arg-type]


def test_no_orthographic_settings(camera: PerspectiveCamera) -> None:
    """The perspective warp has none of the orthographic camera's settings, and its repr
    names its own."""
    warp = PerspectiveWarp(ALPHA, camera._k, camera.distance)
    for name in ("center", "elevation", "camera", "depth_sign"):
        assert not hasattr(warp, name), name
    assert not isinstance(warp, NovelViewWarp)
    assert repr(warp) == (
        "PerspectiveWarp(alpha=10.0, distance=4.0, max_stretch=3.0, line='perpendicular', blend='linear')"
    )


def test_device_and_dtype_kept(scene: tuple, camera: PerspectiveCamera, device: torch.device) -> None:
    """The maps are computed on the correspondences' device; views keep dtype and device."""
    _, seeds, corr = scene
    warp = PerspectiveWarp(ALPHA, camera._k, camera.distance)
    expected = warp(seeds[0], seeds[1], correspondence=corr, thetas=[5.0])
    # Module moves and casts do not touch the camera geometry (a buffer would turn float32).
    warp.to(device).float()
    assert warp.K.dtype == torch.float64 and warp.K.device.type == "cpu"
    for dtype in (torch.float32, torch.float64):
        out = warp(
            seeds[0].to(device, dtype),
            seeds[1].to(device, dtype),
            correspondence=corr.to(device),
            thetas=[5.0],
        )
        assert out.device.type == device.type and out.dtype == dtype
        torch.testing.assert_close(out.cpu().float(), expected, rtol=0, atol=1e-4)
