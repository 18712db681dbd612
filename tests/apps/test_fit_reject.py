"""Rejection of unknown objects through the commands: ``eigview fit`` calibrates it on held-out
synthesized views (``--reject-rate``), ``eigview evaluate --reject`` scores it."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import skimage.io
import torch

from torch_eigview.apps.cli import main
from torch_eigview.datasets import OrthographicCamera, make_object, render_views
from torch_eigview.io.checkpoint import load_recognizer

SIDE = 32
AZIMUTHS = list(range(-40, 41, 10))
KNOWN, UNKNOWN = ("egg", "head"), ("cylinder",)


def _manifest(root: Path, names: tuple[str, ...], azimuths: list[int]) -> Path:
    rows = ["path,object,azimuth"]
    for name in names:
        images = render_views(make_object(name, seed=1), azimuths, OrthographicCamera(SIDE))
        for az, image in zip(azimuths, images, strict=True):
            path = root / name / f"{az % 360}.png"
            path.parent.mkdir(parents=True, exist_ok=True)
            arr = (image[0].clamp(0, 1).numpy() * 255).round().astype(np.uint8)
            skimage.io.imsave(path, arr, check_contrast=False)
            rows.append(f"{name}/{az % 360}.png,{name},{az}")
    out = root / "views.csv"
    out.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return out


@pytest.fixture(scope="module")
def known(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _manifest(tmp_path_factory.mktemp("known"), KNOWN, AZIMUTHS)


@pytest.fixture(scope="module")
def everything(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _manifest(tmp_path_factory.mktemp("all"), KNOWN + UNKNOWN, AZIMUTHS)


def _fit(manifest: Path, out: Path, *extra: str) -> int:
    argv = ["fit", "--manifest", str(manifest), "--seeds", "0", "10", "--synth", "-20", "20", "2"]
    return main([*argv, "-k", "8", "--quiet", *extra, "--out", str(out)])


def test_fit_calibrates_rejection_by_default(
    known: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _fit(known, tmp_path / "m.pt") == 0
    # the summary gives the calibration's own estimate of its rate
    assert re.search(
        r"rejection calibrated on \d+ views \(estimated \d+\.\d% of known views rejected\)",
        capsys.readouterr().out,
    )
    recognizer, meta = load_recognizer(tmp_path / "m.pt")
    # The default held-out poses: 45 degrees before the first seed (0) to 45 past the last (10).
    assert recognizer.rejects and meta["reject_rate"] == 0.05 and meta["reject_poses"] == [-45.0, 55.0, 2.5]
    # The held-out views leave the gallery as it is without rejection.
    assert _fit(known, tmp_path / "plain.pt", "--no-reject") == 0
    plain, meta_plain = load_recognizer(tmp_path / "plain.pt")
    assert not plain.rejects and meta_plain["reject_rate"] is None
    assert torch.equal(plain.codes, recognizer.codes) and torch.equal(plain.poses, recognizer.poses)


def test_evaluate_reject_scores_known_and_unknown_views(
    known: Path, everything: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _fit(known, tmp_path / "m.pt") == 0
    capsys.readouterr()
    argv = ["evaluate", "--model", str(tmp_path / "m.pt"), "--manifest", str(everything), "--quiet"]
    assert main([*argv, "--reject", "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "rejection: known views rejected" in out
    r = json.loads((tmp_path / "r.json").read_text())["rejection"]
    assert r["n_known"] == len(KNOWN) * len(AZIMUTHS) and r["n_unknown"] == len(AZIMUTHS)
    assert r["unknown_rejected"] > r["known_rejected"]
    assert 0.0 <= r["accuracy_accepted"] <= 100.0 and r["thresholds"]["difs"] > 0
    # Without --reject nothing is rejected and the figures are absent.
    assert main([*argv, "--json", str(tmp_path / "plain.json")]) == 0
    assert json.loads((tmp_path / "plain.json").read_text())["rejection"] is None


def test_evaluate_reject_needs_a_calibrated_model(
    known: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _fit(known, tmp_path / "plain.pt", "--no-reject") == 0
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--model", str(tmp_path / "plain.pt"), "--manifest", str(known), "--reject"])
    assert exc.value.code == 2
    assert "--reject needs a model with calibrated rejection" in capsys.readouterr().err


@pytest.mark.parametrize("rate", ["0", "1", "1.5", "nan", "x"])
def test_fit_bad_reject_rate(
    known: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], rate: str
) -> None:
    with pytest.raises(SystemExit) as exc:
        _fit(known, tmp_path / "m.pt", "--reject-rate", rate)
    assert exc.value.code == 2
    assert f"--reject-rate must be a number in (0, 1), got {rate!r}" in capsys.readouterr().err
    assert not (tmp_path / "m.pt").exists()


@pytest.mark.slow
def test_full_circle_held_out_midpoints_leave_the_gallery_unchanged(
    tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
) -> None:
    manifest = _manifest(tmp_path_factory.mktemp("circle"), ("egg",), list(range(0, 360, 90)))
    argv = ["fit", "--manifest", str(manifest), "--circle", "4", "--synth", "0", "360", "15", "-k", "4"]
    assert main([*argv, "--quiet", "--out", str(tmp_path / "m.pt")]) == 0
    assert main([*argv, "--quiet", "--no-reject", "--out", str(tmp_path / "plain.pt")]) == 0
    recognizer, _ = load_recognizer(tmp_path / "m.pt")
    plain, _ = load_recognizer(tmp_path / "plain.pt")
    assert recognizer.rejects and torch.equal(plain.codes, recognizer.codes)
    assert sorted(recognizer.poses.tolist()) == sorted(plain.poses.tolist())
    assert len(plain.poses) == 360 // 15
