"""The optional extras: the core installs and imports without them, and each missing one is
named, with the ``pip install`` to run, where it is needed.

A missing module is simulated with ``sys.modules[name] = None``, which makes ``import name``
raise ImportError as if the package were not installed.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import torch

from torch_eigview import Eigenspace, NearestNeighborRecognizer
from torch_eigview.apps.cli import main
from torch_eigview.io.checkpoint import save_recognizer
from torch_eigview.io.onnx import compare_with_eager, export_onnx, export_projection, read_metadata
from torch_eigview.lazy import require

from tests.helpers import rand

ROOT = Path(__file__).resolve().parents[1]
IMAGE_SHAPE = (1, 4, 5)
ONNX = r"pip install 'torch_eigview\[onnx\]'"
EXTRA_MODULES = ("onnx", "onnxruntime", "onnxscript", "onnx_ir", "sklearn", "matplotlib", "hypothesis")


def missing(monkeypatch: pytest.MonkeyPatch, *names: str) -> None:
    for name in names:
        monkeypatch.setitem(sys.modules, name, None)


@pytest.fixture
def recognizer() -> NearestNeighborRecognizer:
    views = rand(6, *IMAGE_SHAPE, seed=0, dtype=torch.float32)
    layer = Eigenspace(3).fit(views).to_module()
    return NearestNeighborRecognizer.from_views(layer, views, torch.tensor([1, 2] * 3), torch.arange(6.0))


def test_require(monkeypatch: pytest.MonkeyPatch) -> None:
    assert require("json", "onnx", "a test").__name__ == "json"
    missing(monkeypatch, "onnxruntime")
    with pytest.raises(
        ImportError, match=rf"^predicting needs onnxruntime, which is not installed: {ONNX}$"
    ) as info:
        require("onnxruntime", "onnx", "predicting")
    assert info.value.name == "onnxruntime"


def test_export_names_the_onnx_extra(
    monkeypatch: pytest.MonkeyPatch, recognizer: NearestNeighborRecognizer, tmp_path: Path
) -> None:
    path = tmp_path / "p.onnx"
    with monkeypatch.context() as m:
        missing(m, "onnxscript")  # the dynamo exporter needs it
        with pytest.raises(
            ImportError, match=rf"ONNX export needs onnxscript, which is not installed: {ONNX}"
        ):
            export_projection(recognizer.projection, path)
    missing(monkeypatch, "onnx")
    with pytest.raises(ImportError, match=rf"ONNX export needs onnx, which is not installed: {ONNX}"):
        export_onnx(recognizer, path, dynamo=False)
    with pytest.raises(ImportError, match=rf"read_metadata needs onnx, .*{ONNX}"):
        read_metadata(path)
    assert not path.exists()


def test_compare_names_the_onnx_extra(
    monkeypatch: pytest.MonkeyPatch, recognizer: NearestNeighborRecognizer
) -> None:
    missing(monkeypatch, "onnxruntime")
    with pytest.raises(ImportError, match=rf"compare_with_eager needs onnxruntime, .*{ONNX}"):
        compare_with_eager(recognizer, "p.onnx", rand(2, *IMAGE_SHAPE, dtype=torch.float32))


def test_commands_name_the_onnx_extra(
    monkeypatch: pytest.MonkeyPatch,
    recognizer: NearestNeighborRecognizer,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    model = tmp_path / "model.pt"
    save_recognizer(recognizer, model)
    missing(monkeypatch, "onnx", "onnxruntime", "onnxscript")
    for argv, needs in (
        (["export", "--model", str(model), "--out", str(tmp_path / "r.onnx")], "ONNX export needs onnx,"),
        (["predict", "--onnx", str(tmp_path / "r.onnx"), "a.png"], "eigview predict needs onnxruntime,"),
    ):
        with pytest.raises(SystemExit) as info:
            main(argv)
        err = capsys.readouterr().err
        assert info.value.code == 2, err
        assert needs in err and "pip install 'torch_eigview[onnx]'" in err, err
    assert not (tmp_path / "r.onnx").exists()


def test_demo_figure_names_the_plot_extra(
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    recognizer: NearestNeighborRecognizer,
) -> None:
    """Without matplotlib the demo skips its figure, saying which extra draws it."""
    from torch_eigview.apps import demo

    missing(monkeypatch, "matplotlib", "matplotlib.pyplot")
    monkeypatch.setattr(demo, "recognition_experiment", lambda *args, **kwargs: {"recognizer": recognizer})
    record = demo.run_demo(str(tmp_path / "demo.png"), verbose=False)
    assert record["figure"] is None and not (tmp_path / "demo.png").exists()
    out = capsys.readouterr().out
    assert "needs matplotlib" in out and "pip install 'torch_eigview[plot]'" in out, out


@pytest.mark.slow
def test_core_imports_without_the_extras() -> None:
    """Every module but ``torch_eigview.sklearn`` (the [sklearn] extra's own) imports, and every
    public name resolves, with none of the extras' modules importable (a fresh interpreter)."""
    code = (
        "import importlib, pkgutil, sys\n"
        f"for name in {EXTRA_MODULES!r}:\n"
        "    sys.modules[name] = None\n"
        "import torch_eigview, torch_eigview.io\n"
        "for info in pkgutil.walk_packages(torch_eigview.__path__, 'torch_eigview.'):\n"
        "    if info.name not in ('torch_eigview.__main__', 'torch_eigview.sklearn'):\n"
        "        importlib.import_module(info.name)\n"
        "for package in (torch_eigview, torch_eigview.io):\n"
        "    for name in package.__all__:\n"
        "        getattr(package, name)\n"
        "print(torch_eigview.__file__)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert Path(proc.stdout.strip()).parent == ROOT / "torch_eigview"  # this checkout's package


def test_pyproject_extras() -> None:
    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]

    def names(requirements: list[str]) -> set[str]:
        return {r.split("[")[0].split(">")[0].split("=")[0].split("<")[0].strip() for r in requirements}

    core = names(project["dependencies"])
    extras = {k: names(v) for k, v in project["optional-dependencies"].items()}
    assert not core & {"onnx", "onnxruntime", "onnxscript", "matplotlib", "scikit-learn", "hypothesis"}
    assert extras["onnx"] == {"onnx", "onnxruntime", "onnxscript"}
    assert extras["plot"] == {"matplotlib"} and extras["sklearn"] == {"scikit-learn"}
    assert {"torch_eigview", "pytest", "hypothesis", "ruff", "mypy"} <= extras["test"]
    assert "torch_eigview[onnx,sklearn,docs]" in project["optional-dependencies"]["test"]
    assert project["optional-dependencies"]["all"] == ["torch_eigview[onnx,plot,sklearn]"]
