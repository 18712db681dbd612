"""The COIL experiment over worker processes and threads: the same gallery and results as in
one process, its warnings and errors named by object, and the commands' worker policy."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
import torch

import torch_eigview._tuning as _tuning
import torch_eigview.scale.galleries as object_synthesis
from torch_eigview.apps.cli import main
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.scale.parallel import available_cpus, object_workers
from torch_eigview.scale.thread_policy import threads
from torch_eigview.synthesis import ElevationFallbackWarning


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["process", "thread"])
def test_workers_give_the_same_run(folder: CoilFolder, kind: str) -> None:
    """Two spawned workers or two threads: the same gallery, eigenspace and scores as in
    this process, the full circle included (its sectors wrap round)."""
    for kw in ({"alpha": 10.0}, {"seeds": 4, "synth": (0.0, 0.0, 5.0)}):
        here = CoilExperiment(objects=[1, 4, 7], **kw).run(folder)  # type: ignore[arg-type]
        there = CoilExperiment(objects=[1, 4, 7], workers=2, worker_kind=kind, **kw).run(folder)  # type: ignore[arg-type]
        assert there.accuracy == here.accuracy and there.per_object == here.per_object
        assert there.elevations == here.elevations and there.n_train_views == here.n_train_views
        a, b = here.recognizer.state_dict(), there.recognizer.state_dict()
        assert a.keys() == b.keys()
        for key in a:
            same = torch.equal(a[key], b[key]) if isinstance(a[key], torch.Tensor) else a[key] == b[key]
            assert same, key


@pytest.mark.parametrize("workers", [0, 2])
def test_warnings_and_errors_name_the_object(
    folder: CoilFolder, monkeypatch: pytest.MonkeyPatch, workers: int
) -> None:
    """A seed pair's elevation fallback is re-issued with its object, each object's own
    (threads too: one thread's warnings never land with another's object), and a synthesis
    that refuses an object's seeds is an error naming it (the path a worker's results take)."""
    original = object_synthesis.synthesize_views

    def warns(seeds: torch.Tensor, *args: object, **kwargs: object) -> object:
        warnings.warn(
            f"seed pair 0: elevation='auto' could not be measured (seed sum {float(seeds.sum()):.6g})",
            ElevationFallbackWarning,
            stacklevel=1,
        )
        return original(seeds, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(object_synthesis, "synthesize_views", warns)
    objects = [4, 9, 12]
    with pytest.warns(ElevationFallbackWarning) as record:
        CoilExperiment(alpha=10.0, objects=objects, workers=workers, worker_kind="thread").run(folder)
    messages = [str(w.message) for w in record if issubclass(w.category, ElevationFallbackWarning)]
    expected = [
        f"object {o}: seed pair 0: elevation='auto' could not be measured "
        f"(seed sum {float(folder.images(o, [0.0, 10.0]).sum()):.6g})"
        for o in objects
    ]
    assert messages == expected

    def refuses(*args: object, **kwargs: object) -> object:
        raise ValueError("the flow cannot match these views")

    monkeypatch.setattr(object_synthesis, "synthesize_views", refuses)
    with pytest.raises(ValueError, match="object 7: synthesis failed: the flow cannot match"):
        CoilExperiment(alpha=10.0, objects=[7, 8], workers=workers, worker_kind="thread").run(folder)


@pytest.mark.parametrize("workers", [0, 2])
def test_elevation_warnings_of_batched_flows_name_their_object(
    folder: CoilFolder, monkeypatch: pytest.MonkeyPatch, workers: int
) -> None:
    """The objects of a pool job share their flows (one batched call), yet each elevation
    fallback is re-issued with its own object, in the objects' order."""
    import torch_eigview.synthesis.seed_pairs as seed_pairs

    objects = [2, 5, 11]
    monkeypatch.setattr(seed_pairs, "estimate_elevation", lambda *a, **k: torch.tensor([90.0]))
    with pytest.warns(ElevationFallbackWarning) as record:
        CoilExperiment(alpha=10.0, objects=objects, workers=workers, worker_kind="thread").run(folder)
    messages = [str(w.message) for w in record if issubclass(w.category, ElevationFallbackWarning)]
    assert [m.split(":")[0] for m in messages] == [f"object {o}" for o in objects]
    assert all("the fit gave elevation=90" in m for m in messages)


def test_worker_policy() -> None:
    """Processes only for a synthesis worth their start-up, threads whenever there are two
    objects; at most one per object and CPU."""
    cpus = available_cpus()
    with threads(1):
        assert object_workers(820, 128 * 128, 20, kind="thread") == (min(cpus, 20) if cpus >= 2 else 0)
        assert object_workers(820, 128 * 128, 1, kind="thread") == 0
    with threads(2):  # intra-op threads asked for: no worker threads on top
        assert object_workers(820, 128 * 128, 20, kind="thread") == 0
    assert object_workers(820, 128 * 128, 20) == 0  # COIL-20 at one center: 13 M pixels
    big = object_workers(7200, 128 * 128, 20)  # the full circle, M = 8: 118 M pixels
    assert big == (available_cpus() if available_cpus() >= 2 else 0)
    assert object_workers(int(_tuning.PARALLEL_PIXELS), 1, 1) == 0  # one object: nothing to share
    assert object_workers(int(_tuning.PARALLEL_PIXELS), 1, 2) == (
        min(2, available_cpus()) if available_cpus() >= 2 else 0
    )
    assert object_workers(int(_tuning.PARALLEL_PIXELS) - 1, 1, 2) == 0  # just below the threshold


@pytest.mark.parametrize("value", ["-1", "x", "1.5", ""])
def test_bad_workers_flag(value: str, coil_root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["coil", "--folder", str(coil_root), "--alpha", "10", "--workers", value])
    assert exc.value.code == 2
    assert f"--workers must be 'auto' or an integer >= 0, got {value!r}" in capsys.readouterr().err


def test_worker_kind_follows_the_flow() -> None:
    """auto: processes for the scikit-image flows (they hold the GIL), threads for torch's."""
    import argparse

    from torch_eigview.apps.coil_command import _worker_kind

    for flow, kind in (
        ("guided", "thread"),
        ("tvl1", "thread"),
        ("rows", "thread"),
        ("ilk", "process"),
        ("tvl1-skimage", "process"),
    ):
        assert _worker_kind(argparse.Namespace(worker_kind="auto", flow=flow)) == kind
    assert _worker_kind(argparse.Namespace(worker_kind="thread", flow="ilk")) == "thread"


def test_auto_workers_for_the_geometric_pose(folder: CoilFolder) -> None:
    """``--workers auto`` starts threads for a gallery without synthesis (sparse, dense)
    only where they measure the poses (``--pose three-view``)."""
    import argparse

    from torch_eigview.apps.coil_command import _workers

    args = argparse.Namespace(workers="auto", objects=[1, 2, 3])
    want = min(available_cpus(), 3) if available_cpus() >= 2 else 0
    with threads(1):
        for method in ("sparse", "dense"):
            assert _workers(args, CoilExperiment(method=method), folder) == 0
            assert _workers(args, CoilExperiment(method=method, three_view_pose=True), folder) == want
        assert _workers(args, CoilExperiment(), folder) == want
