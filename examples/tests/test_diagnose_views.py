"""The views diagnosis (``examples/diagnostics/diagnose_views.py``): its figures on crafted
sequences whose answers are known, on rendered shapes, on COIL-20, and its bad arguments."""

from __future__ import annotations

import math
from pathlib import Path

import diagnose_views
import pytest
import torch
from diagnose_views import main, pair_view_stats, view_gain_rows

from torch_eigview import SynthesisOptions, SynthesizedViews
from torch_eigview.datasets import OrthographicCamera, make_object, render_views


def _bump(angle: float) -> torch.Tensor:
    """(1, 1, 64) a Gaussian bump at column ``angle``: the real view at that angle."""
    x = torch.arange(64, dtype=torch.float64)
    return torch.exp(-0.5 * ((x - 10 - angle) / 3) ** 2).view(1, 1, 64)


def _fake_synthesis(speed: float, jump_at: float | None = None):  # type: ignore[no-untyped-def]
    """A stand-in for synthesize_views whose view at θ is the real view at ``speed``·θ
    (and, past ``jump_at``, with a second bump: a jump in the sequence)."""

    def synthesize(seeds, alpha, thetas, options=None):  # type: ignore[no-untyped-def]
        views = []
        for t in thetas.tolist():
            v = _bump(speed * t)
            if jump_at is not None and t > jump_at:
                v = v + _bump(40.0)
            views.append(v)
        return SynthesizedViews(torch.stack(views), thetas, [0.0])

    return synthesize


@pytest.mark.parametrize(
    ("speed", "shift", "pull"),
    # Half the motion: the view at 5° looks like the real one at 2.5°, so the real view at
    # 5° is nearest the one synthesized at 10°, pushed away from seed 0 (pull −5). Twice the
    # motion: nearest at 2.5° (its two neighbours tie; argmin takes 2), pulled 3° towards it.
    [(1.0, 0.0, 0.0), (0.5, 5.0, -5.0), (2.0, -3.0, 3.0)],
)
def test_pair_stats_on_known_sequences(
    monkeypatch: pytest.MonkeyPatch, speed: float, shift: float, pull: float
) -> None:
    monkeypatch.setattr(diagnose_views, "synthesize_views", _fake_synthesis(speed))
    seeds = torch.cat([_bump(0.0), _bump(20.0)])
    real = torch.cat([_bump(5.0), _bump(10.0), _bump(15.0)])
    rows, jump = pair_view_stats(seeds, real, 20.0, 5.0, SynthesisOptions())
    d_seed, d_synth, got_shift, got_pull = rows[0]
    assert got_shift == shift and got_pull == pull
    assert rows[1][3] is None  # midway: no nearer seed
    assert d_seed > 0.5  # the bump moved 5 columns, 1.7 of its widths
    if speed == 1.0:
        assert d_synth == 0.0 and all(r[1] == 0.0 and r[2] == 0.0 for r in rows)
        assert math.isclose(jump, 1.0, rel_tol=1e-6)  # equal steps: a smooth sequence
    else:
        assert d_synth > 0.3


def test_jump_finds_a_break_in_the_sequence(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(diagnose_views, "synthesize_views", _fake_synthesis(1.0, jump_at=10.5))
    seeds = torch.cat([_bump(0.0), _bump(20.0)])
    _, jump = pair_view_stats(seeds, _bump(10.0), 20.0, 10.0, SynthesisOptions())
    assert jump > 3.0


def test_rendered_pair_synthesis_comes_nearer_than_the_seeds() -> None:
    """Rendered views of a shape 20° apart: the synthesized views at 5, 10 and 15 degrees are
    nearer the rendered ones than the seeds are, and the nearest synthesized angle is the
    real one within a few degrees."""
    obj, cam = make_object("head"), OrthographicCamera(64)
    views = render_views(obj, [0.0, 5.0, 10.0, 15.0, 20.0], cam)
    rows, jump = pair_view_stats(views[[0, 4]], views[1:4], 20.0, 5.0, SynthesisOptions())
    for d_seed, d_synth, shift, _ in rows:
        assert d_synth < 0.7 * d_seed, rows
        assert abs(shift) <= 3, rows
    assert 1.0 <= jump < 5.0


def test_table_on_coil(coil_root: Path, tmp_path: Path) -> None:
    """On two COIL-20 objects the synthesis gains much at 10° and far less at 45°."""
    argv = ["--root", str(coil_root), "--objects", "1,3", "--centers", "0", "--alphas", "10", "45"]
    rows = main([*argv, "--record", str(tmp_path / "r.json")])
    default = [row for row in rows if row[1] == "default"]
    assert [r[0] for r in default] == [10.0, 45.0]
    gain = {r[0]: float(r[5]) for r in default}
    assert gain[10.0] > 0.2 and gain[45.0] < gain[10.0] - 0.2, rows
    assert default[0][7] is None  # α = 10: the one real view between the seeds is midway
    assert default[1][2] == 2 * 8  # two objects, eight views between seeds 45° apart
    assert (tmp_path / "r.json").is_file()


@pytest.mark.parametrize("alpha", [7.0, 5.0, 0.0, -10.0])
def test_table_rejects_angles_without_a_view_between_seeds(alpha: float) -> None:
    with pytest.raises(ValueError, match=rf"alpha={alpha:g} must be a multiple of the poses' step 5"):
        view_gain_rows(None, [1], [0.0], [alpha])  # type: ignore[arg-type]


@pytest.mark.parametrize("step", [2.5, 0.0, -5.0])
def test_table_rejects_a_step_that_is_not_whole_degrees(step: float) -> None:
    with pytest.raises(ValueError, match=rf"step={step:g} must be a positive whole number of degrees"):
        view_gain_rows(None, [1], [0.0], [10.0], step=step)  # type: ignore[arg-type]


def test_table_needs_objects_centers_angles_and_variants() -> None:
    with pytest.raises(ValueError, match="must each name at least one"):
        view_gain_rows(None, [1], [0.0], [10.0], variants={})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="must each name at least one"):
        view_gain_rows(None, [], [0.0], [10.0])  # type: ignore[arg-type]


def test_cli_bad_angle_is_one_line(capsys: pytest.CaptureFixture[str], coil_root: Path) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--root", str(coil_root), "--objects", "1", "--alphas", "7", "--record", ""])
    assert exc.value.code == 2
    assert "alpha=7 must be a multiple of the poses' step 5" in capsys.readouterr().err


def test_cli_missing_folder_is_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--root", str(tmp_path / "absent"), "--record", ""])
    assert exc.value.code == 2
    assert "absent" in capsys.readouterr().err
