"""The chained-motion diagnosis (``examples/diagnostics/diagnose_chained.py``): its geometry
against the chained motion itself, the full circle's geometry parameter, the experiment
against ``eigview coil``'s with the same geometry, the table on COIL-20 and bad seed poses."""

from __future__ import annotations

from pathlib import Path

import diagnose_chained
import pytest
import torch
from diagnose_chained import chained_geometry, main, run_with_geometry
from diagnose_flow import chained_disparity

from torch_eigview import CoilFolder, SynthesisOptions
from torch_eigview.evaluation import CoilExperiment
from torch_eigview.synthesis import pair_geometry, synthesize_circle


def test_geometry_is_the_chained_motion(folder: CoilFolder) -> None:
    """Each pair's disparities are the motion chained through the views between its seeds
    (both ways), every pixel trusted, with the default flow's elevation."""
    opts = SynthesisOptions()
    geometry = chained_geometry(folder, 1, [0.0, 10.0, 20.0], opts)
    assert len(geometry) == 2
    between = folder.images(1, [10.0, 15.0, 20.0])
    corr = geometry[1].correspondence
    assert torch.equal(corr.disparity_12[0], chained_disparity(between))
    assert torch.equal(corr.disparity_21[0], chained_disparity(between.flip(0)))
    assert bool(corr.valid_12.all()) and bool(corr.valid_21.all())
    assert geometry[1].elevation == pair_geometry(between[[0, -1]], 10.0, opts)[0].elevation


@pytest.mark.parametrize(
    ("poses", "closed", "pair", "chain", "angle"),
    [
        # A pair across 0°: from 340° round through 360° to 10°.
        ([340.0, 10.0], False, 0, [340.0, 345.0, 350.0, 355.0, 0.0, 5.0, 10.0], 30.0),
        # The closing pair of a loop: from the last seed, 350°, round to the first, 0°.
        ([0.0, 10.0, 350.0], True, 2, [350.0, 355.0, 0.0], 10.0),
        # A negative α: from 0° down through 355°.
        ([0.0, -10.0], False, 0, [0.0, 355.0, 350.0], -10.0),
    ],
    ids=["across-0", "closing-pair", "negative-alpha"],
)
def test_pairs_chain_the_short_way_round(
    folder: CoilFolder,
    monkeypatch: pytest.MonkeyPatch,
    poses: list[float],
    closed: bool,
    pair: int,
    chain: list[float],
    angle: float,
) -> None:
    """Each pair chains the views from its first seed to its second the short way round
    (the flow's elevation stood in for: only the motion is checked here)."""
    stand_in = pair_geometry(folder.images(1, [0.0, 10.0]), 10.0, SynthesisOptions())
    angles: list[float] = []

    def flow(seeds: torch.Tensor, alpha: float, options: SynthesisOptions) -> list:  # type: ignore[type-arg]
        angles.append(alpha)
        return stand_in

    monkeypatch.setattr(diagnose_chained, "pair_geometry", flow)
    geometry = chained_geometry(folder, 1, poses, SynthesisOptions(), closed=closed)
    assert len(geometry) == len(poses) - (0 if closed else 1)
    views = folder.images(1, chain)
    assert torch.equal(geometry[pair].correspondence.disparity_12[0], chained_disparity(views))
    assert torch.equal(geometry[pair].correspondence.disparity_21[0], chained_disparity(views.flip(0)))
    assert angles[pair] == angle  # the flow (elevation) sees the pair at its signed angle


@pytest.mark.parametrize(
    ("poses", "match"),
    [
        ([0.0], "at least two seed poses"),
        ([0.0, 12.0], "seed poses 0 and 12 must be a nonzero multiple of the pose step 5 apart"),
        ([10.0, 10.0], "seed poses 10 and 10 must be a nonzero multiple"),
    ],
)
def test_bad_seed_poses_named(folder: CoilFolder, poses: list[float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        chained_geometry(folder, 1, poses, SynthesisOptions())


def test_circle_geometry_parameter(folder: CoilFolder) -> None:
    """The full circle from precomputed geometry gives the views it measures itself."""
    # Half-size views: the geometry's route through the synthesis is what is checked.
    seeds = torch.nn.functional.avg_pool2d(folder.images(2, [0.0, 90.0, 180.0, 270.0]), 2)
    opts = SynthesisOptions()
    geometry = [pair_geometry(seeds[[k, (k + 1) % 4]], 90.0, opts)[0] for k in range(4)]
    own = synthesize_circle(seeds, 20.0, opts)
    given = synthesize_circle(seeds, 20.0, opts, geometry=geometry)
    assert torch.equal(own.views, given.views) and torch.equal(own.thetas, given.thetas)
    with pytest.raises(ValueError, match=r"geometry must hold one record per seed pair \(M = 4\), got 2"):
        synthesize_circle(seeds, 20.0, opts, geometry=geometry[:2])


@pytest.mark.parametrize(
    "base",
    [
        CoilExperiment(alpha=10.0, center=90.0, objects=[1, 3], synth=(-10.0, 10.0, 5.0), components=5),
        CoilExperiment(seeds=4, objects=[3], synth=(0.0, 0.0, 30.0), interpolate_pose=True, components=3),
    ],
    ids=["center-90", "circle"],
)
def test_experiment_with_the_flows_geometry_is_eigview_coils(
    folder: CoilFolder, base: CoilExperiment
) -> None:
    """Given the default flow's geometry instead of the chained motion, the experiment
    reproduces ``eigview coil``'s run exactly: its galleries differ in the geometry alone."""
    calls: list[int] = []

    def flow_geometry(folder, obj, poses, options, *, closed=False, step=5.0):  # type: ignore[no-untyped-def]
        calls.append(obj)
        seeds = folder.images(obj, list(poses))
        pairs = [(k, k + 1) for k in range(len(poses) - 1)] + ([(len(poses) - 1, 0)] if closed else [])
        alpha = (poses[1] - poses[0]) % 360.0
        return [pair_geometry(seeds[[i, j]], alpha, options)[0] for i, j in pairs]

    ours, n_gallery = run_with_geometry(base, folder, flow_geometry)
    theirs = base.run(folder)
    assert calls == list(base.objects)  # the galleries came from the geometry given
    assert ours.accuracy == theirs.accuracy and ours.per_object == theirs.per_object
    assert ours.pose_mae_deg == theirs.pose_mae_deg and ours.pose_median_deg == theirs.pose_median_deg
    assert n_gallery == theirs.n_train_views


def test_table_on_coil(coil_root: Path, tmp_path: Path) -> None:
    """Two objects, one center (no full circle: its chains are long): one row, accuracies in [0, 100]."""
    argv = ["--root", str(coil_root), "--objects", "1,3", "--centers", "90", "--seeds"]
    rows = main([*argv, "--components", "5", "--record", str(tmp_path / "r.json")])
    assert [row[0] for row in rows] == ["center 90"]
    assert all(0.0 <= v <= 100.0 for row in rows for v in row[1:4])
    assert (tmp_path / "r.json").is_file()
