"""The synthetic protocol's helpers (``examples/paper/synthetic.py``): the galleries per camera
model and background, the recognition experiment and its ceiling."""

from __future__ import annotations

import pytest
import torch
from synthetic import (
    PAPER_FIG2,
    angle_range,
    camera_warp,
    default_camera,
    format_table,
    intrinsics,
    recognition_experiment,
    run_protocol,
    synthetic_gallery,
)

from torch_eigview import NovelViewWarp, PerspectiveWarp
from torch_eigview.datasets import Backdrop, OrthographicCamera, PerspectiveCamera, SyntheticScene

SHAPES = ("head", "egg", "cylinder")


def test_small_experiment() -> None:
    scene = SyntheticScene(shapes=("head", "cylinder"), camera=OrthographicCamera(32))
    result = recognition_experiment(10.0, 2, scene=scene, correspondences="exact", test=(-10.0, 10.0))
    assert result["n_test"] == 42 and result["n_gallery"] == 82
    assert result["accuracy"] == 100.0
    table = format_table([result], PAPER_FIG2).splitlines()
    assert table[1].split()[:3] == ["10", "2", "exact"] and table[-1] == "O1=head, O2=cylinder"


def test_rendered_gallery_is_the_ceiling() -> None:
    """``correspondences="rendered"``: the gallery is the rendered views at the gallery's
    angles (no synthesis): its codes are those of the renders, not of synthesized views,
    and test views at the gallery's angles are then recognized with their exact pose."""
    shapes = ("head", "cylinder")
    scene = SyntheticScene(shapes=shapes, camera=OrthographicCamera(24))
    result = recognition_experiment(
        10.0, 2, scene=scene, correspondences="rendered", synth=(-10.0, 10.0, 1.0), test=(-10.0, 10.0)
    )
    assert result["n_gallery"] == 42 and result["accuracy"] == 100.0
    assert result["pose_mae_deg"] == 0.0
    rec = result["recognizer"]
    assert isinstance(rec, torch.nn.Module)
    renders = torch.cat([scene.views(n, angle_range(-10.0, 10.0, 1.0)) for n in shapes])
    torch.testing.assert_close(rec.codes, rec.projection(renders))
    synthesized = recognition_experiment(
        10.0, 2, scene=scene, correspondences="exact", synth=(-10.0, 10.0, 1.0), test=(-10.0, 10.0)
    )
    other = synthesized["recognizer"]
    assert isinstance(other, torch.nn.Module)
    assert not torch.allclose(other.projection(renders), other.codes, atol=1e-3)
    with pytest.raises(
        ValueError, match=r"correspondences must be one of \('flow', 'exact', 'rendered'\), got 'true'"
    ):
        recognition_experiment(10.0, 2, scene=scene, correspondences="true")


def test_three_views_range_follows_the_seeds() -> None:
    scene = SyntheticScene(shapes=("egg",), camera=OrthographicCamera(24))
    views, thetas = synthetic_gallery(scene, "egg", 10.0, 3, correspondences="exact")
    assert thetas[0] == -25.0 and thetas[-1] == 25.0 and views.shape[0] == 51
    # The seeds (-10, 0, 10) come out as rendered: each seed pair reproduces its own views.
    seeds = scene.views("egg", [-10.0, 0.0, 10.0])
    torch.testing.assert_close(views[[15, 25, 35]], seeds, rtol=0, atol=1e-5)


def test_camera_warps() -> None:
    """Each camera model's warp: Eq. 7, the affine solve, trifocal transfer with the
    camera's intrinsics (the default ones as the camera documents them)."""
    assert type(camera_warp(default_camera("orthographic", 24), 10.0)) is NovelViewWarp
    assert type(camera_warp(default_camera("affine", 24), 10.0)) is NovelViewWarp
    assert isinstance(camera_warp(default_camera("perspective", 24), 10.0), PerspectiveWarp)
    camera = PerspectiveCamera(24, distance=4.0)
    point = torch.tensor([[0.3, -0.2, 0.5]], dtype=torch.float64)
    x, y, _ = camera.project(point)
    cam = torch.stack([point[:, 0], -point[:, 1], camera.distance - point[:, 2]], dim=-1)
    q = cam @ intrinsics(camera).T
    torch.testing.assert_close(torch.cat([x, y]), torch.cat([q[:, 0] / q[:, 2], q[:, 1] / q[:, 2]]))
    with pytest.raises(ValueError, match="unknown camera name='fisheye'"):
        default_camera("fisheye")


def test_backdrop_protocol_matches_the_black_background() -> None:
    """Masks given reproduce the black-background views exactly; estimated ones come within a
    point of the black background's accuracy."""
    cam = OrthographicCamera(24)
    black = SyntheticScene(shapes=SHAPES, camera=cam)
    given = SyntheticScene(shapes=SHAPES, camera=cam, backdrop=Backdrop(), masks="given")
    estimated = SyntheticScene(shapes=SHAPES, camera=cam, backdrop=Backdrop(), masks="estimated")
    angles = [0.0, 10.0, -20.0]
    assert torch.equal(given.views("egg", angles), black.views("egg", angles))

    def accuracy(scene: SyntheticScene) -> float:
        record = recognition_experiment(
            10.0, 2, scene=scene, components=8, synth=(-10.0, 10.0, 2.0), test=(-15.0, 15.0)
        )
        return float(record["accuracy"])  # type: ignore[arg-type]

    a = accuracy(black)
    assert abs(accuracy(given) - a) <= 1.0
    assert abs(accuracy(estimated) - a) <= 1.0
    views_b, _ = synthetic_gallery(black, "head", 10.0, synth=(-10.0, 10.0, 5.0))
    views_g, _ = synthetic_gallery(given, "head", 10.0, synth=(-10.0, 10.0, 5.0))
    # Exact masks against the threshold's: the silhouettes differ by a few dark pixels at most.
    assert float((views_g - views_b).abs().mean()) < 2e-3


def test_perspective_gallery_on_the_backdrop() -> None:
    """The 2D warp of the perspective camera takes the scene's masks for silhouette-aware sampling."""
    scene = SyntheticScene(
        shapes=("egg",), camera=PerspectiveCamera(24), backdrop=Backdrop(), masks="estimated"
    )
    views, thetas = synthetic_gallery(scene, "egg", 10.0, synth=(0.0, 10.0, 5.0), correspondences="exact")
    assert views.shape == (3, 1, 24, 24) and thetas == [0.0, 5.0, 10.0]
    outside = ~scene.foreground("egg", [0.0])[0]
    assert torch.equal(views[0, 0][outside], torch.zeros_like(views[0, 0][outside]))


@pytest.mark.parametrize("camera", ["affine", "perspective"])
def test_protocol_per_camera(camera: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Fig. 2's protocol with each camera model's synthesis, the ceiling and the synthesis error."""
    out = run_protocol(
        camera, [10.0], [2], size=40, shapes=("egg", "cylinder"), test=(-20.0, 20.0), error_thetas=(-5.0, 4.0)
    )
    (record,) = out["results"]  # type: ignore[misc]
    assert record["n_test"] == 82 and record["accuracy"] >= 95.0
    errors = [e for errs in out["synthesis_error"].values() for e in errs]  # type: ignore[attr-defined]
    assert len(errors) == 4 and max(errors) < 0.02
    (ceiling,) = out["ceiling"]  # type: ignore[misc]
    assert ceiling["correspondences"] == "rendered" and ceiling["n_gallery"] == record["n_gallery"]
    printed = capsys.readouterr().out
    assert f"camera model: {camera}" in printed and "per-pixel mean abs error" in printed
    assert "ceiling: the same protocol with the rendered views" in printed


def test_protocol_checks_the_background() -> None:
    with pytest.raises(ValueError, match=r"background='grey' must be one of \('black', 'textured'\)"):
        run_protocol(background="grey", alphas=(10.0,), views=(2,), verbose=False)
