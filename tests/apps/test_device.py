"""``--device`` on ``eigview fit``, ``evaluate`` and ``predict --model``: the errors everywhere,
the CUDA runs (against the CPU's) where a GPU is present."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from torch_eigview.apps.device_option import device_arg, resolve_device
from torch_eigview.io.checkpoint import load_recognizer

from tests.apps.test_fit_evaluate import _fit_args
from tests.helpers import rendered_turntable, run_cli

SIDE = 32
AZIMUTHS = list(range(-40, 41, 10))
CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA not available")


@pytest.fixture(scope="module")
def views(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two rendered objects every 10 degrees over -40..40, as PNGs listed in views.csv."""
    return rendered_turntable(tmp_path_factory.mktemp("views"), AZIMUTHS, SIDE)


@pytest.fixture(scope="module")
def model(views: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from torch_eigview.apps.cli import main

    out = tmp_path_factory.mktemp("model") / "model.pt"
    assert main(_fit_args(views, out, "--device", "cpu")) == 0
    return out


def _commands(views: Path, model: Path, out: Path) -> dict[str, list[str]]:
    image = str(views.parent / "egg" / "0.png")
    return {
        "fit": _fit_args(views, out),
        "evaluate": ["evaluate", "--model", str(model), "--manifest", str(views)],
        "predict": ["predict", "--model", str(model), image],
    }


@pytest.mark.parametrize("value", ["gpu", "cuda:x", "cuda:-1", "cpu:0:1", ""])
def test_malformed_device_is_named(
    value: str, views: Path, model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "m.pt"
    for name, argv in _commands(views, model, out).items():
        code, _, err = run_cli([*argv, "--device", value], capsys)
        assert code == 2, name
        assert "--device must be cpu, cuda, cuda:N" in err and repr(value) in err, (name, err)
    assert not out.exists()


def test_device_arg_and_resolve() -> None:
    assert device_arg("CUDA:1") == "cuda:1" and device_arg("cpu") == "cpu" and device_arg("auto") == "auto"
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("auto") == torch.device("cuda" if torch.cuda.is_available() else "cpu")


@pytest.mark.parametrize("value", ["cuda", "cuda:0", "cuda:1"])
def test_cuda_without_a_gpu_is_named(
    value: str,
    views: Path,
    model: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without CUDA (made so here, whatever the machine), each command exits 2 before any
    work, naming --device and the remedy, and fit writes nothing."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    out = tmp_path / "m.pt"
    for name, argv in _commands(views, model, out).items():
        code, stdout, err = run_cli([*argv, "--device", value], capsys)
        assert code == 2, (name, stdout, err)
        assert f"--device {value}: no CUDA device is available; use --device cpu" in err, (name, err)
    assert not out.exists()


def test_device_goes_with_model_only(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(
        ["predict", "--onnx", str(tmp_path / "m.onnx"), "x.png", "--device", "cpu"], capsys
    )
    assert code == 2 and "--device cpu applies to --model only" in err


def test_cpu_device_runs(
    views: Path, model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "r.json"
    argv = ["evaluate", "--model", str(model), "--manifest", str(views), "--json", str(report)]
    code, out, _ = run_cli([*argv, "--device", "cpu"], capsys)
    assert code == 0, out
    assert json.loads(report.read_text())["accuracy"] >= 80.0
    code, out, err = run_cli(["predict", "--model", str(model), str(views.parent / "egg" / "0.png")], capsys)
    assert code == 0 and "label egg" in out, err


@CUDA
def test_cuda_fit_evaluate_predict_match_cpu(
    views: Path, model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """On CUDA: the same model as on the CPU (to float32 rounding, TF32 off), the same scores
    and answers, and the file loads on the CPU."""
    torch.backends.cuda.matmul.allow_tf32 = False
    cuda_model = tmp_path / "cuda.pt"
    code, out, err = run_cli(_fit_args(views, cuda_model, "--device", "cuda"), capsys)
    assert code == 0, err
    on_cpu, _ = load_recognizer(model)
    on_cuda, _ = load_recognizer(cuda_model)
    assert on_cuda.codes.device.type == "cpu"
    assert torch.equal(on_cuda.labels, on_cpu.labels) and torch.equal(on_cuda.poses, on_cpu.poses)
    # Codes up to each component's sign, which the two devices' solvers may pick apart.
    signs = torch.sign((on_cuda.codes * on_cpu.codes).sum(dim=0))
    torch.testing.assert_close(on_cuda.codes * signs, on_cpu.codes, atol=1e-3, rtol=1e-3)
    reports = {}
    for device in ("cpu", "cuda"):
        report = tmp_path / f"{device}.json"
        argv = ["evaluate", "--model", str(model), "--manifest", str(views), "--json", str(report)]
        code, out, _ = run_cli([*argv, "--device", device], capsys)
        assert code == 0, out
        reports[device] = json.loads(report.read_text())
    assert reports["cuda"]["accuracy"] == reports["cpu"]["accuracy"]
    images = [str(views.parent / name / "20.png") for name in ("egg", "head")]
    answers = {}
    for device in ("cpu", "cuda:0"):
        report = tmp_path / f"p{device[-1]}.json"
        argv = ["predict", "--model", str(model), *images, "--json", str(report), "--device", device]
        code, _, err = run_cli(argv, capsys)
        assert code == 0, err
        answers[device] = json.loads(report.read_text())
    for a, b in zip(answers["cpu"], answers["cuda:0"], strict=True):
        assert a["label"] == b["label"] and a["pose"] == b["pose"]
        assert a["distance"] == pytest.approx(b["distance"], rel=1e-3, abs=1e-5)
