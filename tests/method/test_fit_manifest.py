"""Your own objects in Python: ``FewViewEigenspace.fit_manifest`` reads a manifest as ``eigview
fit`` does, and one model file serves both ways (fitted in Python, predicted by ``eigview
predict --model``; fitted by ``eigview fit``, loaded and predicted in Python)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from torch_eigview import FewViewEigenspace, NotFittedError
from torch_eigview.apps.cli import main
from torch_eigview.datasets import (
    ViewDataset,
    ViewManifest,
    read_images,
    read_seed_views,
)
from torch_eigview.io import Preprocessing, load_model

from tests.helpers import rendered_turntable

SIDE = 32
AZIMUTHS = list(range(-40, 41, 10))
SYNTH = (-20.0, 20.0, 2.0)


@pytest.fixture(scope="module")
def views(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two rendered objects every 10 degrees over -40..40, as PNGs listed in views.csv."""
    return rendered_turntable(tmp_path_factory.mktemp("own"), AZIMUTHS, SIDE)


def _test_files(views: Path) -> list[str]:
    return [str(views.parent / name / f"{az % 360}.png") for name in ("egg", "head") for az in (-30, 20, 40)]


def _predicted(capsys: pytest.CaptureFixture[str], argv: list[str]) -> list[tuple[str, str, float, float]]:
    """``eigview predict``'s rows: (image, label, pose, distance)."""
    capsys.readouterr()
    assert main(argv) == 0
    rows = []
    for line in capsys.readouterr().out.splitlines():
        image, label, pose, distance = line.split("\t")
        rows.append((image, label.removeprefix("label "), float(pose.split()[1]), float(distance.split()[1])))
    return rows


def test_fitted_in_python_predicts_from_the_command(
    views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    est = FewViewEigenspace(8, synth=SYNTH).fit_manifest(ViewManifest.from_csv(views), [0, 10])
    assert est.label_names_ == ["egg", "head"]
    assert est.preprocessing_ == Preprocessing((SIDE, SIDE), 1)
    assert est.seed_azimuths_ == [0.0, 10.0]
    files = _test_files(views)
    mine = est.predict_files(files)
    names = [est.label_names_[int(i)] for i in mine.labels]
    assert names == ["egg"] * 3 + ["head"] * 3

    est.save(tmp_path / "model.pt")
    rows = _predicted(capsys, ["predict", "--model", str(tmp_path / "model.pt"), *files])
    assert [r[1] for r in rows] == names
    assert [r[2] for r in rows] == pytest.approx(mine.poses.tolist(), abs=1e-4)
    assert [r[3] for r in rows] == pytest.approx(mine.distances.tolist(), rel=1e-4)
    # evaluate reads the seeds the Python fit recorded.
    assert (
        main(["evaluate", "--model", str(tmp_path / "model.pt"), "--manifest", str(views), "--exclude-seeds"])
        == 0
    )


def test_fitted_by_the_command_loads_and_predicts_in_python(
    views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "model.pt"
    argv = ["fit", "--manifest", str(views), "--seeds", "0", "10", "--synth", "-20", "20", "2", "-k", "8"]
    assert main([*argv, "--quiet", "--out", str(out)]) == 0
    files = _test_files(views)
    rows = _predicted(capsys, ["predict", "--model", str(out), *files])

    model = load_model(out)
    result = model.predict_files(files)
    names = {label: name for name, label in model.label_table().items()}
    assert [names[int(i)] for i in result.labels] == [r[1] for r in rows]
    assert result.poses.tolist() == pytest.approx([r[2] for r in rows], abs=1e-4)
    assert result.distances.tolist() == pytest.approx([r[3] for r in rows], rel=1e-4)

    # The command and fit_manifest are one path: the same settings give the same model.
    est = FewViewEigenspace(8, synth=SYNTH, reject_rate=0.05).fit_manifest(
        ViewManifest.from_csv(views), [0, 10]
    )
    assert est.preprocessing_ == model.preprocessing
    torch.testing.assert_close(est.recognizer_.codes, model.recognizer.codes, rtol=1e-4, atol=1e-5)
    assert torch.equal(est.predict_files(files).labels, result.labels)


def test_a_view_dataset_gives_its_size_and_channels(views: Path) -> None:
    dataset = ViewDataset(ViewManifest.from_csv(views), (16, 16), channels=3)
    seeds = read_seed_views(dataset, [0, 10])
    assert seeds.preprocessing == Preprocessing((16, 16), 3)
    assert [tuple(v.shape) for v in seeds.views] == [(2, 3, 16, 16)] * 2
    assert seeds.masks == [None, None] and seeds.reason == "no masks given"
    est = FewViewEigenspace(4, synth=SYNTH).fit_manifest(seeds)
    assert est.preprocessing_ is not None
    images = read_images(_test_files(views)[:2], est.preprocessing_)
    assert images.shape == (2, 3, 16, 16)
    assert torch.equal(est.predict_files(_test_files(views)[:2]).labels, est.predict(images).labels)


def test_seed_angles_follow_the_wrapped_steps(views: Path) -> None:
    seeds = read_seed_views(ViewManifest.from_csv(views), [350, 10], background="auto")
    assert seeds.angles == [-10.0, 10.0] and seeds.azimuths == [350.0, 10.0]
    assert seeds.preprocessing.background == "auto" and seeds.reason == "as given"
    assert all(m is not None and m.dtype == torch.bool for m in seeds.masks)


def test_bad_calls_name_the_argument(views: Path, tmp_path: Path) -> None:
    manifest = ViewManifest.from_csv(views)
    est = FewViewEigenspace(4, synth=SYNTH)
    with pytest.raises(NotFittedError, match="before save"):
        est.save(tmp_path / "m.pt")
    with pytest.raises(NotFittedError, match="before predict_files"):
        est.predict_files(_test_files(views))
    with pytest.raises(TypeError, match="fit_manifest needs seeds"):
        est.fit_manifest(manifest)
    with pytest.raises(TypeError, match="manifest must be a ViewManifest or a ViewDataset, got str"):
        est.fit_manifest(str(views), [0, 10])
    with pytest.raises(ValueError, match=r"seeds=\[0.0\] needs two or more azimuths"):
        est.fit_manifest(manifest, [0])
    with pytest.raises(ValueError, match="background must be None, 'keep', 'auto' or a colour"):
        est.fit_manifest(manifest, [0, 10], background="white")
    with pytest.raises(ValueError, match=r"background colour must be 1 or 3 values in \[0, 1\]"):
        est.fit_manifest(manifest, [0, 10], background=(0, 0, 255))
    with pytest.raises(ValueError, match=r"tolerance=0\.1 goes with background 'auto' or a colour"):
        est.fit_manifest(manifest, [0, 10], background="keep", tolerance=0.1)
    with pytest.raises(
        ValueError, match=r"tolerance=0\.1 goes with background 'auto' or a colour; the views"
    ):
        est.fit_manifest(manifest, [0, 10], tolerance=0.1)
    with pytest.raises(ValueError, match="object 'egg' has no view at the seed azimuth 15 degrees"):
        est.fit_manifest(manifest, [0, 15])
    with pytest.raises(TypeError, match=r"size\[0\] \(H\) must be an integer, got float 1.5"):
        est.fit_manifest(manifest, [0, 10], size=(1.5, 8))
    seeds = read_seed_views(manifest, [0, 10])
    with pytest.raises(ValueError, match="seeds, size cannot be given with SeedViews"):
        est.fit_manifest(seeds, [0, 10], size=(8, 8))
    with pytest.raises(TypeError, match="preprocessing must be a Preprocessing, got tuple"):
        read_images(_test_files(views), (SIDE, SIDE))  # type: ignore[arg-type]
    est.fit_manifest(seeds)
    with pytest.raises(TypeError, match="metadata must be a mapping"):
        est.save(tmp_path / "m.pt", ["not", "a", "mapping"])  # type: ignore[arg-type]


def test_a_fit_on_tensors_saves_the_pixels_as_read(views: Path, tmp_path: Path) -> None:
    seeds = read_seed_views(ViewManifest.from_csv(views), [0, 10])
    est = FewViewEigenspace(4, synth=SYNTH).fit(seeds.views, seeds.angles, labels=seeds.objects)
    assert est.preprocessing_ is None and est.seed_azimuths_ is None
    est.save(tmp_path / "m.pt", {"note": "tensors"})
    model = load_model(tmp_path / "m.pt")
    assert model.preprocessing == Preprocessing((SIDE, SIDE), 1)
    assert model.metadata["note"] == "tensors" and "seed_azimuths" not in model.metadata
    files = _test_files(views)
    assert torch.equal(model.predict_files(files).labels, est.predict_files(files).labels)
