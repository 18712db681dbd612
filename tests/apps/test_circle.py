"""Tests for the full circle: its layout, the three methods on 2 objects, and bad input."""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
from pathlib import Path

import pytest
import torch

from torch_eigview.apps.cli import main
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.evaluation.circle import circle_layout
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.synthesis import SynthesisOptions, synthesize_circle

COIL20 = [5.0 * i for i in range(72)]
OBJECTS = [1, 2]


def test_layout_of_eight_seeds() -> None:
    layout = circle_layout(COIL20, 10.0, 8, "nvs")
    assert layout.alpha == 45.0
    assert layout.seeds == [10.0 + 45.0 * k for k in range(8)]
    assert layout.real == layout.seeds
    assert len(layout.tests) == 72 - 8 and not set(layout.tests) & set(layout.seeds)
    # The seeds wrap: center 350 puts the second seed at 35.
    assert circle_layout(COIL20, 350.0, 8, "sparse").seeds[:2] == [350.0, 35.0]


@pytest.mark.parametrize(("m", "step"), [(4, 45.0), (6, 30.0), (8, 20.0), (12, 15.0)])
def test_dense_default_is_about_two_m_views(m: int, step: float) -> None:
    layout = circle_layout(COIL20, 0.0, m, "dense")
    assert layout.real == [step * j for j in range(math.ceil(360 / step))]
    assert len(layout.tests) == 72 - len(layout.real)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((1, "nvs", None), r"seeds=1 must be >= 2"),
        ((73, "sparse", None), r"seeds=73 must be <= 72"),
        (
            (7, "sparse", None),
            r"seeds=7 from center=0 puts seed views at \[51.429.*between the available poses \[0, 5",
        ),
        ((2, "nvs", None), r"seeds=2 puts the seed views 180 degrees apart"),
        ((4, "dense", 7.0), r"dense_step=7 must be a positive multiple of the poses' step 5"),
        ((4, "dense", -5.0), r"dense_step=-5 must be a positive multiple"),
    ],
)
def test_layout_errors(args: tuple[int, str, float | None], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        circle_layout(COIL20, 0.0, *args)


def test_synthesize_circle_sectors() -> None:
    """Every sector from its own pair; each seed's own view is the identity warp of it."""
    g = torch.Generator().manual_seed(0)
    seeds = torch.zeros(4, 1, 16, 16)
    seeds[:, :, 4:12, 5:11] = torch.rand(4, 1, 8, 6, generator=g) * 0.8 + 0.2
    out = synthesize_circle(seeds, 30.0, SynthesisOptions(elevation=0.0, extent=False))
    assert out.views.shape == (12, 1, 16, 16)
    assert out.thetas.tolist() == [30.0 * i for i in range(12)]
    assert out.pairs.tolist() == [k for k in range(4) for _ in range(3)]
    torch.testing.assert_close(out.views[::3], seeds, atol=1e-5, rtol=0)
    assert len(out.elevations) == 4


@pytest.mark.slow
@pytest.mark.coil
@pytest.mark.parametrize(("method", "n_gallery"), [("nvs", 360 // 15), ("sparse", 4), ("dense", 8)])
def test_circle_run(folder: CoilFolder, method: str, n_gallery: int) -> None:
    exp = CoilExperiment(
        seeds=4,
        method=method,
        objects=OBJECTS,
        components=3,
        synth=(0.0, 0.0, 15.0),
        synthesis=SynthesisOptions(elevation=0.0),
    )
    result = exp.run(folder)
    assert result.n_train_views == len(OBJECTS) * n_gallery
    assert result.n_test == len(OBJECTS) * (72 - (8 if method == "dense" else 4))
    gallery = set(result.recognizer.poses.tolist())
    assert {0.0, 90.0, 180.0, -90.0} <= gallery
    record = result.to_json()
    assert set(record["pose_error_deg"]) == {"mean", "median"}  # type: ignore[arg-type]
    assert record["pose_error_deg"]["mean"] == result.pose_mae_deg  # type: ignore[index]
    assert 0 <= result.pose_median_deg <= 180 and 50.0 <= result.accuracy <= 100.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(seeds=1), "seeds=1 must be >= 2"),
        (dict(seeds=4, views=3), "seeds=4 places its own seed views: it cannot take views=3"),
        (dict(dense_step=10.0, method="dense"), "dense_step=10.0 is the full circle's dense baseline"),
        (dict(seeds=4, dense_step=10.0), "it needs seeds and method 'dense'"),
        (dict(overlap=5.0), "overlap=5.0 extends the full circle's sectors: it needs seeds"),
    ],
)
def test_config_errors(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        CoilExperiment(**kwargs)  # type: ignore[arg-type]


@pytest.mark.coil
@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--circle", "1"], "--circle=1 must be >= 2"),
        (["--circle", "73"], "--circle=73 must be <= 72"),
        (["--circle", "7"], r"--circle=7 from center=0 puts seed views at \[51.429"),
        (
            ["--circle", "8", "--center", "2"],
            r"between the available poses \[0, 5, 10, 15, ..., 350, 355\] \(72 poses\)",
        ),
        (["--circle", "4", "--views", "3"], "--circle 4 places its own seed views: it cannot take --views 3"),
        (["--circle", "4", "--alpha", "10"], "--alpha 10 contradicts --circle 4"),
        ([], "--alpha is required"),
    ],
)
def test_cli_errors(
    coil_root: Path, extra: list[str], match: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as info:
        main(["coil", "--folder", str(coil_root), "--objects", "1-2", *extra])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("eigview: error: ")
    assert re.search(match, err), err


@pytest.mark.coil
def test_cli_sparse_circle_json(coil_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    with contextlib.redirect_stdout(io.StringIO()) as text:
        status = main(
            ["coil", "--folder", str(coil_root), "--objects", "1-2", "--circle", "6", "--method", "sparse",
             "--components", "3", "--json", str(out)]
        )  # fmt: skip
    assert status == 0 and "full circle, 6 seed views from center=0" in text.getvalue()
    record = json.loads(out.read_text())
    assert record["n_train_views"] == 12 and record["n_test"] == 2 * 66
    assert set(record["pose_error_deg"]) == {"mean", "median"}


def test_synthesize_circle_overlap() -> None:
    """With an overlap each pair also extrapolates past both of its seeds; its views inside
    the sector stay those without one."""
    g = torch.Generator().manual_seed(0)
    seeds = torch.zeros(6, 1, 16, 16)
    seeds[:, :, 4:12, 5:11] = torch.rand(6, 1, 8, 6, generator=g) * 0.8 + 0.2
    opts = SynthesisOptions(elevation=0.0, extent=False)
    plain = synthesize_circle(seeds, 15.0, opts)
    out = synthesize_circle(seeds, 15.0, opts, overlap=15.0)
    # Per pair (alpha = 60): -15 and 75 past its seeds, 0, 15, 30, 45 in its sector.
    assert out.views.shape == (6 * 6, 1, 16, 16)
    assert out.thetas[:6].tolist() == [345.0, 0.0, 15.0, 30.0, 45.0, 75.0]
    assert out.thetas[6:12].tolist() == [45.0, 60.0, 75.0, 90.0, 105.0, 135.0]
    assert out.pairs.tolist() == [k for k in range(6) for _ in range(6)]
    inside = torch.tensor([t % 6 not in (0, 5) for t in range(36)])
    torch.testing.assert_close(out.views[inside], plain.views, atol=1e-6, rtol=0)


@pytest.mark.parametrize(("m", "overlap"), [(6, -1.0), (6, 31.0), (6, float("nan")), (4, 15.0)])
def test_synthesize_circle_overlap_errors(m: int, overlap: float) -> None:
    with pytest.raises(ValueError, match="overlap"):
        synthesize_circle(torch.rand(m, 1, 8, 8), 15.0, SynthesisOptions(elevation=0.0), overlap=overlap)


def test_experiment_overlap_checked_against_the_layout(folder: CoilFolder) -> None:
    with pytest.raises(ValueError, match=r"overlap=31 must be in \[0, alpha/2 = 30\]"):
        CoilExperiment(seeds=6, overlap=31.0).circle(folder, [1])
    with pytest.raises(TypeError, match="overlap"):
        CoilExperiment(seeds=6, overlap="5")  # type: ignore[arg-type]
