"""``eigview fit`` / ``evaluate`` / ``predict --model`` on manifests of rendered objects, their
bad inputs, and COIL-20 through a manifest against ``eigview coil``."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import skimage.io
import torch

from torch_eigview.apps.cli import main
from torch_eigview.datasets import OrthographicCamera, make_object, render_views
from torch_eigview.io.checkpoint import load_recognizer
from torch_eigview.io.preprocessing import Preprocessing

from tests.helpers import rendered_turntable, run_cli

SIDE = 32
PREDICT_NO_TORCH = (
    "import sys; from torch_eigview.apps.cli import main; rc = main(sys.argv[1:]); "
    "assert 'torch' not in sys.modules, 'predict imported torch'; sys.exit(rc)"
)
AZIMUTHS = list(range(-40, 41, 10))


def _png(path: Path, image: torch.Tensor) -> str:
    path.parent.mkdir(parents=True, exist_ok=True)
    arr = (image[0].clamp(0, 1).numpy() * 255).round().astype(np.uint8)
    skimage.io.imsave(path, arr, check_contrast=False)
    return str(path)


def _write(path: Path, rows: list[str]) -> Path:
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def views(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two rendered objects every 10 degrees over -40..40, as PNGs listed in views.csv."""
    return rendered_turntable(tmp_path_factory.mktemp("views"), AZIMUTHS, SIDE)


def _fit_args(views: Path, out: Path, *extra: str) -> list[str]:
    return [
        "fit", "--manifest", str(views), "--seeds", "0", "10", "--synth", "-20", "20", "2",
        "--quiet", *extra, "--out", str(out),
    ]  # fmt: skip


@pytest.fixture(scope="module")
def model(views: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("model") / "model.pt"
    assert main(_fit_args(views, out)) == 0
    return out


def test_fit_records_preprocessing_labels_and_seeds(model: Path) -> None:
    recognizer, meta = load_recognizer(model)
    assert recognizer.label_names == ["egg", "head"]
    assert Preprocessing.from_json(meta["preprocessing"]) == Preprocessing((SIDE, SIDE), 1)
    assert meta["seed_azimuths"] == [0.0, 10.0]
    # Two seeds: the --synth range from the first seed, every 2 degrees, per object.
    assert recognizer.codes.shape[0] == 2 * 21
    assert sorted(set(recognizer.poses.tolist())) == [float(a) for a in range(-20, 21, 2)]


def test_fit_default_range_reaches_past_both_seeds(views: Path, tmp_path: Path) -> None:
    """Without --synth: every degree from 20 before the first seed to 20 past the last, recorded."""
    out = tmp_path / "m.pt"
    argv = ["fit", "--manifest", str(views), "--seeds", "0", "30", "-k", "4", "--no-reject", "--quiet"]
    assert main([*argv, "--out", str(out)]) == 0
    recognizer, meta = load_recognizer(out)
    assert sorted(set(recognizer.poses.tolist())) == [float(a) for a in range(-20, 51)]
    assert meta["synth"] == [-20.0, 50.0, 1.0]


def test_evaluate_scores_every_view_and_excludes_seeds(
    model: Path, views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "r.json"
    code, out, _ = run_cli(
        ["evaluate", "--model", str(model), "--manifest", str(views), "--json", str(report)], capsys
    )
    assert code == 0, out
    record = json.loads(report.read_text())
    assert record["n_test"] == 2 * len(AZIMUTHS)
    assert set(record["per_object"]) == {"egg", "head"}
    assert record["accuracy"] == pytest.approx(np.mean(list(record["per_object"].values())))
    assert record["accuracy"] >= 80.0  # two objects: chance is 50
    assert 0.0 <= record["pose_error_deg"]["median"] <= record["pose_error_deg"]["mean"] + 20
    assert record["skipped"] == [] and record["rejection"] is None
    code, _, _ = run_cli(
        [
            "evaluate",
            "--model",
            str(model),
            "--manifest",
            str(views),
            "--exclude-seeds",
            "--json",
            str(report),
        ],
        capsys,
    )
    assert code == 0 and json.loads(report.read_text())["n_test"] == 2 * (len(AZIMUTHS) - 2)


def test_evaluate_reports_bad_rows_and_goes_on(
    model: Path, views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = views.parent
    (tmp_path / "corrupt.png").write_bytes(b"not a png")
    mask = np.zeros((SIDE + 1, SIDE), np.uint8)
    skimage.io.imsave(tmp_path / "mask.png", mask, check_contrast=False)
    rows = ["path,object,azimuth,mask"] + [
        f"{base}/{o}/{a % 360}.png,{o},{a}," for o in ("egg", "head") for a in AZIMUTHS
    ]
    rows += [
        f"{tmp_path}/gone.png,egg,5,",  # line 20: a missing file
        f"{tmp_path}/corrupt.png,egg,15,",  # line 21: not an image
        f"{base}/egg/0.png,egg,25,{tmp_path}/mask.png",  # line 22: a mask of another size
        f"{base}/egg/0.png,egg,ten,",  # line 23: a non-numeric angle
        f"{base}/egg/0.png,egg,0,",  # line 24: duplicates line 6
        f"{base}/egg/0.png,cat,0,",  # an object the model does not know
    ]
    manifest = _write(tmp_path / "bad.csv", rows)
    report = tmp_path / "r.json"
    code, out, err = run_cli(
        ["evaluate", "--model", str(model), "--manifest", str(manifest), "--json", str(report)], capsys
    )
    assert code == 1
    record = json.loads(report.read_text())
    assert record["n_test"] == 2 * len(AZIMUTHS)
    rows_skipped = {r["row"] for r in record["skipped"]}
    assert rows_skipped == {f"{manifest} line {n}" for n in (20, 21, 22, 23, 24)}
    errors = " ".join(r["error"] for r in record["skipped"])
    for needle in (
        "gone.png does not exist",
        "is not an image file that can be read",
        "has size",
        "azimuth='ten'",
        "duplicates",
    ):
        assert needle in errors
    assert record["unknown_objects"] == {"cat": 1}
    assert "bad.csv line 22" in err and "rows skipped: 5" in out


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (
            ["--seeds", "0", "15"],
            r"object 'egg' has no view at the seed azimuth 15 degrees .*azimuths 0, 10, 20",
        ),
        (["--circle", "8"], r"object 'egg' has no view at the seed azimuth 45 degrees"),
        (["--seeds", "2"], r"--seeds 2 needs two or more azimuths.*--circle M"),
        (["--seeds", "0", "360"], r"repeats an azimuth"),
        (["--seeds", "0", "10", "--synth", "0", "10", "0"], r"--synth"),
    ],
)
def test_fit_bad_seeds(
    views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], match: str
) -> None:
    args = ["fit", "--manifest", str(views), *argv, "--quiet", "--out", str(tmp_path / "m.pt")]
    code, _, err = run_cli(args, capsys)
    assert code == 2
    assert re.search(match, err), err
    assert not (tmp_path / "m.pt").exists()


def test_fit_object_with_fewer_views_than_seeds(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    image = render_views(make_object("egg"), [0.0], OrthographicCamera(16))[0]
    _png(tmp_path / "a.png", image)
    _png(tmp_path / "b.png", image)
    manifest = _write(
        tmp_path / "m.csv", ["path,object,azimuth", "a.png,egg,0", "b.png,egg,10", "a.png,cup,0"]
    )
    code, _, err = run_cli(
        ["fit", "--manifest", str(manifest), "--seeds", "0", "10", "--out", str(tmp_path / "m.pt")], capsys
    )
    assert code == 2
    assert "object 'cup' has 1 view(s) in" in err and "fewer than the 2 seeds: azimuths 0" in err


def test_fit_checks_output_and_inputs_first(
    views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(_fit_args(views, tmp_path / "missing" / "m.pt"), capsys)
    assert code == 2 and "--out" in err and "does not exist" in err
    code, _, err = run_cli(_fit_args(views, views), capsys)  # would overwrite the manifest
    assert code == 2 and "same file as --manifest" in err
    code, _, err = run_cli(
        ["fit", "--pattern", "{object}/{azimuth}.png", "--seeds", "0", "10", "--out", str(tmp_path / "m.pt")],
        capsys,
    )
    assert code == 2 and "--pattern" in err and "needs --root" in err


def test_fit_pattern_equals_manifest(views: Path, model: Path, tmp_path: Path) -> None:
    out = tmp_path / "p.pt"
    argv = _fit_args(views, out)
    argv[1:3] = ["--pattern", "{object}/{azimuth}.png", "--root", str(views.parent)]
    assert main(argv) == 0
    a, _ = load_recognizer(model)
    b, _ = load_recognizer(out)
    torch.testing.assert_close(a.codes, b.codes)
    assert a.label_names == b.label_names


@pytest.mark.slow
def test_predict_model_and_onnx_apply_the_recorded_preprocessing(
    model: Path, views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("onnxruntime")
    # A 2x larger RGB copy of a view: predict resizes it and converts it to gray.
    gray = skimage.io.imread(views.parent / "head" / "20.png")
    big = np.kron(gray, np.ones((2, 2), np.uint8))
    skimage.io.imsave(tmp_path / "big.png", np.stack([big] * 3, -1), check_contrast=False)
    images = [str(views.parent / "egg" / "350.png"), str(tmp_path / "big.png")]
    onnx_path = tmp_path / "m.onnx"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["export", "--model", str(model), "--out", str(onnx_path), "--recognizer"]) == 0
    capsys.readouterr()
    answers = {}
    for flag, path in (("--model", model), ("--onnx", onnx_path)):
        report = tmp_path / f"{flag[2:]}.json"
        code, _, err = run_cli(["predict", flag, str(path), *images, "--json", str(report)], capsys)
        assert code == 0, err
        answers[flag] = json.loads(report.read_text())
    assert [r["label"] for r in answers["--model"]] == ["egg", "head"]
    for a, b in zip(answers["--model"], answers["--onnx"], strict=True):
        assert a["label"] == b["label"] and a["pose"] == b["pose"]
        assert a["distance"] == pytest.approx(b["distance"], rel=1e-3, abs=1e-5)
    # Torch-free, with a missing file among the images: reported, the others answered.
    argv = [
        "predict",
        "--onnx",
        str(onnx_path),
        images[0],
        str(tmp_path / "gone.png"),
        images[1],
        "--debug-modules",
    ]
    proc = subprocess.run(
        [sys.executable, "-c", PREDICT_NO_TORCH, *argv], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 1, proc.stderr
    assert "torch imported: False" in proc.stderr and "gone.png does not exist" in proc.stderr
    assert [line.split("\t")[1] for line in proc.stdout.splitlines()] == ["label egg", "label head"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("coil_args", "seeds", "tested"),
    [
        (["--alpha", "10"], ["--seeds", "0", "10"], range(-45, 50, 5)),
        (["--alpha", "10", "--views", "3"], ["--seeds", "0", "10", "20"], range(-45, 50, 5)),
        (["--circle", "8"], ["--circle", "8"], [a for a in range(0, 360, 5) if a % 45]),
    ],
    ids=["two-seeds", "three-seeds", "circle-8"],
)
def test_coil_through_a_manifest_equals_eigview_coil(
    coil_root: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    coil_args: list[str],
    seeds: list[str],
    tested: list[int],
) -> None:
    """The must-hold: fit + evaluate over a manifest of COIL files give eigview coil's table."""
    objects = (1, 4, 7)
    listed = ["path,object,azimuth"] + [
        f"{coil_root}/obj{o}__{p}.png,{o},{5 * p}" for o in objects for p in range(72)
    ]
    tests = ["path,object,azimuth"] + [
        f"{coil_root}/obj{o}__{(a % 360) // 5}.png,{o},{a}" for o in objects for a in tested
    ]
    coil_json, eval_json, model = tmp_path / "coil.json", tmp_path / "eval.json", tmp_path / "m.pt"
    synth = ["--synth", "-20", "20", "2"]
    coil_argv = ["coil", "--folder", str(coil_root), *coil_args, "--objects", "1,4,7", *synth]
    assert main([*coil_argv, "--quiet", "--json", str(coil_json)]) == 0
    fit_argv = ["fit", "--manifest", str(_write(tmp_path / "all.csv", listed)), *seeds]
    assert main([*fit_argv, *synth, "--quiet", "--out", str(model)]) == 0
    manifest = _write(tmp_path / "test.csv", tests)
    assert (
        main(["evaluate", "--model", str(model), "--manifest", str(manifest), "--json", str(eval_json)]) == 0
    )
    capsys.readouterr()
    coil, ev = json.loads(coil_json.read_text()), json.loads(eval_json.read_text())
    assert ev["per_object"] == coil["per_object"]
    assert ev["accuracy"] == coil["accuracy"]
    assert ev["pose_error_deg"] == coil["pose_error_deg"]
    assert ev["n_test"] == coil["n_test"]
