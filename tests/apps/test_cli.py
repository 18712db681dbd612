"""Tests for the ``eigview`` command: a small COIL run, its outputs, and exit status 2 on bad input."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import skimage.io

from torch_eigview.apps.cli import main
from torch_eigview.apps.cli_args import progress_bar
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.io.checkpoint import load_recognizer
from torch_eigview.io.model import model_preprocessing

# Two objects, seeds at 0 and 10 degrees, 4 synthesized views each, 5 test views each.
SMALL = [
    "--alpha", "10",
    "--synth", "-5", "10", "5",
    "--test", "-10", "10",
    "--objects", "1-2",
    "--components", "3",
    "--elevation", "0",
]  # fmt: skip


@pytest.fixture(scope="module")
def small_run(coil_root: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """Runs ``eigview coil ... --json --save`` once; capsys is per test, so capture here."""
    out_dir = tmp_path_factory.mktemp("cli")
    json_path, model_path = out_dir / "result.json", out_dir / "model.pt"
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        status = main(
            ["coil", "--folder", str(coil_root), *SMALL, "--json", str(json_path), "--save", str(model_path)]
        )
    return {"status": status, "stdout": stdout.getvalue(), "json": json_path, "model": model_path}


@pytest.mark.coil
def test_run_writes_json(small_run: dict[str, object]) -> None:
    assert small_run["status"] == 0
    record = json.loads(Path(small_run["json"]).read_text())  # type: ignore[arg-type]
    assert set(record) == {
        "accuracy",
        "per_object",
        "pose_mae_deg",
        "pose_error_deg",
        "n_test",
        "n_train_views",
        "seconds",
    }
    assert set(record["per_object"]) == {"1", "2"}
    assert record["n_test"] == 2 * 5
    assert record["n_train_views"] == 2 * 4
    assert 0.0 <= record["accuracy"] <= 100.0
    assert set(record["seconds"]) == {"correspondence", "synthesis", "eigen", "recognition", "total"}


@pytest.mark.coil
def test_run_saves_loadable_model(small_run: dict[str, object], coil_root: Path) -> None:
    from torch_eigview.datasets.coil import CoilFolder

    rec, meta = load_recognizer(small_run["model"])  # type: ignore[arg-type]
    record = json.loads(Path(small_run["json"]).read_text())  # type: ignore[arg-type]
    assert meta == {"command": "coil", "alpha": 10.0, "method": "nvs", "accuracy": record["accuracy"]}
    assert rec.n_gallery == record["n_train_views"]
    assert rec.projection.unit_norm is True and rec.projection.n_components == 3
    # The saved model recognizes object 2's real 0-degree view as object 2.
    view = CoilFolder(coil_root).images(2, [0.0])
    assert rec.predict(view).labels.tolist() == [2]


@pytest.mark.coil
def test_run_prints_table(small_run: dict[str, object]) -> None:
    text = str(small_run["stdout"])
    record = json.loads(Path(small_run["json"]).read_text())  # type: ignore[arg-type]
    lines = text.splitlines()
    assert lines[0].startswith("COIL nvs: alpha=10, 2 seed views")
    rows = {line.split()[0]: line for line in lines if line.split() and line.split()[0] in {"O1", "O2"}}
    assert set(rows) == {"O1", "O2"}
    for obj in ("1", "2"):
        assert float(rows[f"O{obj}"].split()[1]) == pytest.approx(record["per_object"][obj], abs=0.005)
    total = [line for line in lines if line.split() and line.split()[0] == "Total"]
    assert len(total) == 1
    assert float(total[0].split()[1]) == pytest.approx(record["accuracy"], abs=0.005)
    assert "test images 10, gallery views 8" in text


def _exit_status(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    with pytest.raises(SystemExit) as info:
        main(argv)
    return int(info.value.code), capsys.readouterr().err  # type: ignore[arg-type]


def test_empty_root(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, err = _exit_status(["coil", "--folder", str(tmp_path), "--alpha", "10"], capsys)
    assert code == 2
    assert "holds no COIL files" in err and str(tmp_path) in err


def test_missing_root(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, err = _exit_status(["coil", "--folder", str(tmp_path / "nope"), "--alpha", "10"], capsys)
    assert code == 2
    assert "must be an existing directory" in err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--components", "0"], "--components must be an int >= 1 or a fraction in (0, 1)"),
        (["--components", "many"], "--components must be an int or a fraction in (0, 1)"),
        (["--objects", "5-3"], "reversed range 5-3"),
        (["--objects", "a"], "must look like '1-20'"),
        (["--elevation", "up"], "--elevation must be 'auto' or a finite number of degrees"),
        (["--views", "4"], "invalid choice: 4"),
        (["--method", "knn"], "invalid choice: 'knn'"),
        (["--pose-step", "0"], "--pose-step must be a number of degrees in (0, 360], got '0'"),
        (["--pose-step", "ten"], "--pose-step must be a finite number, got 'ten'"),
    ],
    ids=[
        "components-0",
        "components-text",
        "objects-reversed",
        "objects-text",
        "elevation",
        "views",
        "method",
        "pose-step-0",
        "pose-step-text",
    ],
)
def test_bad_arguments(
    extra: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Argument errors come before the folder is read; the folder is a real (empty) one anyway.
    code, err = _exit_status(["coil", "--folder", str(tmp_path), "--alpha", "10", *extra], capsys)
    assert code == 2
    assert message in err


def test_missing_arguments(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert _exit_status([], capsys)[0] == 2
    # Without --folder the images are looked for in $TORCH_EIGVIEW_DATA/coil-20-proc: absent here.
    monkeypatch.setenv("TORCH_EIGVIEW_DATA", str(tmp_path))
    code, err = _exit_status(["coil", "--alpha", "10"], capsys)
    assert code == 2 and "--folder" in err
    assert str(tmp_path / "coil-20-proc") in err and "TORCH_EIGVIEW_DATA" in err
    assert "Traceback" not in err


def test_a_turntable_of_36_views_every_10_degrees(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--pose-step 10`` reads indices 0..35 as 0..350 degrees; the tests and the dense
    gallery take every available view (10 degrees apart), and without the flag the
    command warns and reads them 5 degrees apart (0..175: -20 is not a pose)."""
    rng = np.random.default_rng(0)
    for obj in (1, 2):
        for p in range(36):
            skimage.io.imsave(
                tmp_path / f"obj{obj}__{p}.png",
                rng.integers(0, 256, (12, 12), dtype=np.uint8),
                check_contrast=False,
            )
    json_path = tmp_path / "out" / "r.json"
    json_path.parent.mkdir()
    args = [
        "coil",
        "--folder",
        str(tmp_path),
        "--alpha",
        "20",
        "--synth",
        "-20",
        "40",
        "1",
        "--test",
        "-40",
        "40",
    ]
    args += ["--method", "dense", "--components", "3", "--quiet", "--json", str(json_path)]
    assert main([*args, "--pose-step", "10"]) == 0
    result = json.loads(json_path.read_text())
    assert result["n_test"] == 2 * 9 and result["n_train_views"] == 2 * 7
    code, err = _exit_status(args, capsys)
    assert code == 2 and "pass pose_step=10 (eigview coil --pose-step 10)" in err
    assert "no image at degrees=-20.0" in err and "[0, 5, 10, ..., 170, 175]" in err


def test_a_gray_backdrop_set_to_zero(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--background R,G,B`` keys a backdrop out of every view the run reads (seeds, tests,
    real galleries); ``--tolerance`` without it, or a colour that is not one, is an error."""
    for obj in (1, 2):
        for p in range(72):
            img = np.full((12, 12), 110, dtype=np.uint8)
            img[3:9, 2 + obj + p % 3 : 7 + obj + p % 3] = 60 * obj
            skimage.io.imsave(tmp_path / f"obj{obj}__{p}.png", img, check_contrast=False)
    json_path = tmp_path / "out" / "r.json"
    json_path.parent.mkdir()
    args = ["coil", "--folder", str(tmp_path), "--alpha", "10", "--test", "-10", "10", "--method", "dense"]
    args += ["--components", "3", "--quiet", "--json", str(json_path)]
    model_path = tmp_path / "out" / "model.pt"
    assert main([*args, "--background", "110", "--tolerance", "8", "--save", str(model_path)]) == 0
    assert json.loads(json_path.read_text())["n_test"] == 2 * 5
    # The saved model records the rule, so predict and evaluate key the backdrop out too.
    recognizer, meta = load_recognizer(model_path)
    prep = model_preprocessing(recognizer, meta, str(model_path))
    assert (prep.background, prep.colour, prep.tolerance) == ("colour", (110 / 255,), 8 / 255)
    assert prep.image_shape == (1, 12, 12)
    code, err = _exit_status([*args, "--tolerance", "8"], capsys)
    assert code == 2 and "--tolerance goes with --background auto or R,G,B, not with keep" in err
    code, err = _exit_status([*args, "--background", "gray"], capsys)
    assert code == 2 and "--background 'gray' must be keep, auto, or a colour R,G,B" in err


def test_root_from_env(coil_root: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--folder`` defaults to ``$TORCH_EIGVIEW_DATA/coil-20-proc``; the flag wins over it."""
    from torch_eigview.evaluation import coil as experiment

    seen: list[Path] = []

    def run(self: object, folder: CoilFolder, progress: object = None) -> None:
        seen.append(folder.root)
        raise ValueError("stop here")  # the folder was found; the experiment itself is tested above

    monkeypatch.setattr(experiment.CoilExperiment, "run", run)
    monkeypatch.setenv("TORCH_EIGVIEW_DATA", str(coil_root.parent))
    with pytest.raises(SystemExit):
        main(["coil", "--alpha", "10"])
    monkeypatch.setenv("TORCH_EIGVIEW_DATA", "/no/such/folder")
    with pytest.raises(SystemExit):
        main(["coil", "--alpha", "10", "--folder", str(coil_root)])
    assert seen == [coil_root, coil_root]


@pytest.mark.coil
@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--alpha", "0", "--objects", "1"], "alpha=0.0 must not be a multiple of 180 degrees"),
        (["--alpha", "10", "--synth", "0", "10", "-1"], "synth step must be positive, got -1.0"),
        (["--alpha", "10", "--objects", "1,99", "--method", "sparse"], "objects [99] are not in"),
    ],
    ids=["alpha_zero", "negative_synth_step", "unknown_object"],
)
def test_bad_experiment_arguments(
    coil_root: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    code, err = _exit_status(["coil", "--folder", str(coil_root), *extra], capsys)
    assert code == 2
    assert message in err


@pytest.mark.slow
@pytest.mark.coil
def test_module_entry_point(coil_root: Path, tmp_path: Path) -> None:
    argv = [
        sys.executable, "-m", "torch_eigview", "coil",
        "--folder", str(coil_root),
        "--alpha", "10",
        "--synth", "0", "5", "5",
        "--test", "0", "5",
        "--objects", "1-2",
        "--components", "2",
        "--elevation", "0",
        "--json", str(tmp_path / "r.json"),
    ]  # fmt: skip
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Total" in proc.stdout and "O1" in proc.stdout and "O2" in proc.stdout
    record = json.loads((tmp_path / "r.json").read_text())
    assert record["n_test"] == 4 and record["n_train_views"] == 4

    bad = subprocess.run(
        [sys.executable, "-m", "torch_eigview", "coil", "--folder", str(tmp_path), "--alpha", "10"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert bad.returncode == 2 and "holds no COIL files" in bad.stderr


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_progress_bar_only_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert progress_bar(False, "objects", "obj") is None  # a pipe or a log: no bar
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert progress_bar(True, "objects", "obj") is None  # --quiet
    bar = progress_bar(False, "objects", "obj")
    assert bar is not None
    assert list(bar(range(3))) == [0, 1, 2]
    assert "objects:" in terminal.getvalue() and "/3 [" in terminal.getvalue()  # the bar was drawn


@pytest.mark.parametrize("quiet", [False, True], ids=["terminal", "quiet"])
@pytest.mark.parametrize("command", ["demo"])
def test_demo_gets_progress(command: str, quiet: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """``eigview demo`` hands its loop a tqdm bar on a terminal, none with --quiet."""
    from torch_eigview.apps import demo

    calls: list[object] = []

    def fake(*args: object, progress: object = None, **kwargs: object) -> dict[str, object]:
        calls.append(progress)
        return {}

    monkeypatch.setattr(demo, f"run_{command}", fake)
    monkeypatch.setattr(sys, "stderr", _Terminal())
    argv = [command, "--png", ""] if command == "demo" else [command]
    assert main([*argv, *(["--quiet"] if quiet else [])]) == 0
    assert len(calls) == 1 and (calls[0] is None) == quiet


def test_demo_loop_reports_each_object() -> None:
    """The demo's progress wrapper sees every object of the scene, in order."""
    from torch_eigview.apps.demo import recognition_experiment
    from torch_eigview.datasets import OrthographicCamera, SyntheticScene

    seen: list[str] = []

    def progress(names: object) -> object:
        for name in names:  # type: ignore[attr-defined]
            seen.append(name)
            yield name

    scene = SyntheticScene(shapes=("head", "egg"), camera=OrthographicCamera(24))
    record = recognition_experiment(
        10.0,
        scene=scene,
        components=3,
        synth=(-5.0, 5.0, 5.0),
        test=(0.0, 2.0),
        progress=progress,
    )
    assert seen == ["head", "egg"]
    assert record["n_gallery"] == 2 * 3


def test_ctrl_c_ends_with_a_line_not_a_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C while a command writes: exit status 130 and the writer's own message (which
    says the previous file is unchanged), never a traceback."""
    import torch_eigview.apps.cli as cli

    def interrupted(args: object) -> int:
        raise KeyboardInterrupt("could not write 'm.pt' (interrupted); any previous file is unchanged")

    monkeypatch.setattr(cli, "run_fit", interrupted)
    with pytest.raises(SystemExit) as exit_info:
        main(["fit", "--manifest", "views.csv", "--seeds", "0", "10", "--out", "m.pt"])
    assert exit_info.value.code == 130
    err = capsys.readouterr().err
    assert "eigview: interrupted: could not write 'm.pt' (interrupted); any previous file is unchanged" in err
    assert "Traceback" not in err
