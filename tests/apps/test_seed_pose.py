"""``eigview coil --pose three-view``: the recognized views' poses measured again by Eq. 2
against the recognized object's seed views (``SeedPoses``), on COIL-20."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest
import torch

import torch_eigview.evaluation.coil as experiment
import torch_eigview.evaluation.scoring as protocol
from torch_eigview.apps.cli import main
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.evaluation.seed_pose import SeedPoses
from torch_eigview.scale.thread_policy import threads
from torch_eigview.synthesis import SynthesisOptions

# The sparse gallery (the two seeds alone) gives each view one of two poses, so the
# geometric pose has much to correct; tests inside and just beyond the 10° sector.
SMALL = ["--method", "sparse", "--alpha", "10", "--test", "-5", "15", "--objects", "1-3", "--components", "3"]


def _run(coil_root: Path, tmp_path: Path, pose: str) -> dict[str, object]:
    path = tmp_path / f"{pose}.json"
    with contextlib.redirect_stdout(io.StringIO()):
        status = main(
            ["coil", "--folder", str(coil_root), *SMALL, "--pose", pose, "--json", str(path), "--quiet"]
        )
    assert status == 0
    return json.loads(path.read_text())


@pytest.mark.coil
def test_three_view_pose_from_the_command(coil_root: Path, tmp_path: Path) -> None:
    """The same recognition, and a pose error below the appearance manifold's (measured on
    objects 1-3: mean 1.21° against 2.88°, median 0.40° against 0.97°; the nearest gallery
    view's: 3.67° and 5°)."""
    rough, geometric = _run(coil_root, tmp_path, "interpolate"), _run(coil_root, tmp_path, "three-view")
    assert geometric["accuracy"] == rough["accuracy"] and geometric["per_object"] == rough["per_object"]
    err_rough, err_geo = rough["pose_error_deg"], geometric["pose_error_deg"]
    assert isinstance(err_rough, dict) and isinstance(err_geo, dict)
    assert err_geo["mean"] < 0.75 * err_rough["mean"]
    assert err_geo["median"] < 1.0


@pytest.mark.slow
@pytest.mark.coil
def test_three_view_pose_over_worker_threads(folder: CoilFolder, monkeypatch: pytest.MonkeyPatch) -> None:
    """The experiment's workers measure the poses as threads, one object each (not as
    processes, nor off the CPU): the same scores and pose errors as in this thread (both
    under the commands' one torch thread)."""
    given: list[int] = []

    def spy(*args: object, workers: int = 0, **kwargs: object) -> object:
        given.append(workers)
        return protocol.score(*args, workers=workers, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(experiment, "score", spy)
    base = dict(alpha=10.0, test=(-5.0, 15.0), objects=[1, 2, 3], components=3, method="sparse")
    with threads(1):
        here = CoilExperiment(three_view_pose=True, **base).run(folder)  # type: ignore[arg-type]
        there = CoilExperiment(three_view_pose=True, workers=2, **base).run(folder)  # type: ignore[arg-type]
        CoilExperiment(workers=2, worker_kind="process", **base).run(folder)  # type: ignore[arg-type]
    assert given == [0, 2, 0]
    assert there.per_object == here.per_object
    assert (there.pose_mae_deg, there.pose_median_deg) == (here.pose_mae_deg, here.pose_median_deg)


def test_experiment_passes_its_seeds(folder: CoilFolder, monkeypatch: pytest.MonkeyPatch) -> None:
    """The experiment hands the scorer a SeedPoses over its own seed poses: the per-center
    seeds (open) or the circle's (closed)."""
    seen: list[SeedPoses] = []

    def spy(self: SeedPoses, views: torch.Tensor, labels: torch.Tensor, rough: torch.Tensor) -> torch.Tensor:
        seen.append(self)
        return rough.double()

    monkeypatch.setattr(SeedPoses, "__call__", spy)
    opts = SynthesisOptions(elevation=0.0)
    base = dict(objects=[1], components=1, method="sparse", three_view_pose=True, synthesis=opts)
    CoilExperiment(alpha=10.0, center=90.0, test=(-5.0, 5.0), **base).run(folder)  # type: ignore[arg-type]
    CoilExperiment(seeds=4, **base).run(folder)  # type: ignore[arg-type]
    assert [(list(s.seed_poses), s.closed) for s in seen] == [
        ([90.0, 100.0], False),
        ([0.0, 90.0, 180.0, 270.0], True),
    ]
    assert all(s.options is opts for s in seen)


def test_two_seeds_round_the_circle_are_refused_before_any_work(
    folder: CoilFolder, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Seeds 180° apart leave Eq. 2 singular: refused when the run starts, before a gallery
    is built; the flags must be bools."""

    def no_gallery(*args: object, **kwargs: object) -> None:
        raise AssertionError("the gallery was built")

    monkeypatch.setattr(CoilExperiment, "_gallery_inputs", no_gallery)
    with pytest.raises(ValueError, match="at least 3 seeds round the circle, got 2"):
        CoilExperiment(seeds=2, method="sparse", objects=[1], three_view_pose=True).run(folder)
    with pytest.raises(TypeError, match="interpolate_pose, three_view_pose must be bools"):
        CoilExperiment(three_view_pose=1)  # type: ignore[arg-type]
