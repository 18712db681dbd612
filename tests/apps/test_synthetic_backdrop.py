"""The Fig. 2 protocol on the coloured, textured backdrop, with given and estimated masks."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from torch_eigview.apps.cli import main
from torch_eigview.apps.demo import recognition_experiment, run_synth
from torch_eigview.apps.synthetic_scene import SyntheticScene, synthetic_gallery
from torch_eigview.datasets import Backdrop, OrthographicCamera, PerspectiveCamera

SHAPES = ("head", "egg", "cylinder")


def _accuracy(scene: SyntheticScene) -> float:
    record = recognition_experiment(
        10.0, 2, scene=scene, components=8, synth=(-10.0, 10.0, 2.0), test=(-15.0, 15.0)
    )
    return float(record["accuracy"])  # type: ignore[arg-type]


@pytest.mark.slow
def test_backdrop_protocol_matches_the_black_background() -> None:
    """Masks given reproduce the black-background views exactly; estimated ones come within a point."""
    cam = OrthographicCamera(32)
    black = SyntheticScene(shapes=SHAPES, camera=cam)
    given = SyntheticScene(shapes=SHAPES, camera=cam, backdrop=Backdrop(), masks="given")
    estimated = SyntheticScene(shapes=SHAPES, camera=cam, backdrop=Backdrop(), masks="estimated")
    angles = [0.0, 10.0, -20.0]
    assert torch.equal(given.views("egg", angles), black.views("egg", angles))
    a = _accuracy(black)
    assert abs(_accuracy(given) - a) <= 1.0
    assert abs(_accuracy(estimated) - a) <= 1.0
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


def test_scene_rejects_unknown_masks() -> None:
    with pytest.raises(ValueError, match=r"masks='exact' must be one of \('given', 'estimated'\)"):
        SyntheticScene(backdrop=Backdrop(), masks="exact")
    with pytest.raises(ValueError, match=r"background='grey' must be one of \('black', 'textured'\)"):
        run_synth(background="grey", alphas=(10.0,), views=(2,), verbose=False)


@pytest.mark.slow
def test_synth_command_on_the_backdrop(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    argv = ["synth", "--alpha", "10", "--views", "2", "--size", "24", "--shapes", "egg,head", "--quiet"]
    assert main([*argv, "--background", "textured", "--masks", "estimated", "--json", str(out)]) == 0
    record = json.loads(out.read_text())
    assert record["background"] == "textured" and record["masks"] == "estimated"
    assert record["results"][0]["n_test"] == 2 * 90
