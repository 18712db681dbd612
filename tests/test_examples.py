"""The examples run (quick settings), so they cannot rot; every script at least imports."""

from __future__ import annotations

import importlib.util
import itertools
from pathlib import Path
from types import ModuleType

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
# Every script of examples/ and export/; each runs its work under ``if __name__ == "__main__"``.
SCRIPTS = sorted([*EXAMPLES.glob("*.py"), *(ROOT / "export").glob("*.py")])


def load_path(path: Path) -> ModuleType:
    """Imports a script as a module (its ``__name__`` is not ``"__main__"``: nothing runs)."""
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def load(name: str) -> ModuleType:
    return load_path(EXAMPLES / f"{name}.py")


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_script_imports(path: Path) -> None:
    """The package names a script imports exist (they move when the package is reorganised)."""
    module = load_path(path)
    assert callable(getattr(module, "main", None)), f"{path.name} has no main()"


COIL_EXAMPLES = [
    "reject_unknown",
    "kernel_pca",
    "train_frozen_features",
    "warp_augmentation",
]


@pytest.mark.parametrize("name", COIL_EXAMPLES)
def test_missing_data_says_where(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without the images a COIL example exits 2 naming the folder, the variable and the flag."""
    monkeypatch.setenv("TORCH_EIGVIEW_DATA", str(tmp_path))
    with pytest.raises(SystemExit) as info:
        load(name).main([])
    err = capsys.readouterr().err
    assert info.value.code == 2
    assert str(tmp_path / "coil-20-proc") in err and "TORCH_EIGVIEW_DATA" in err and "--root" in err
    with pytest.raises(SystemExit) as info:
        load(name).main(["--root", str(tmp_path / "nope")])
    assert info.value.code == 2 and "must be an existing directory" in capsys.readouterr().err


@pytest.mark.coil
def test_train_frozen_features(coil_root: Path, tmp_path: Path) -> None:
    """The head on the frozen layer, trained from a DataLoader over a ViewDataset under
    autocast, against the nearest-neighbour recognizer on the same real test views."""
    import json

    record = tmp_path / "train.json"
    # aot_eager: the same torch.compile path (Dynamo + AOTAutograd) without inductor's C++ build.
    result = load("train_frozen_features").main(
        ["--root", str(coil_root), "--quick", "--compile-backend", "aot_eager", "--record", str(record)]
    )
    assert result["n_test"] == 3 * 19 and result["n_train"] == 3 * 2
    assert result["accuracy"] >= 90.0 and result["nn_accuracy"] >= 90.0
    assert result["autocast"] == ("float16" if result["device"].startswith("cuda") else "bfloat16")
    assert result["compile_err"] < 1e-4 and result["dtype_err"] < 1e-6
    saved = json.loads(record.read_text())
    rows = saved["tables"][0]["rows"]
    assert [r[1] for r in rows] == [result["accuracy"], result["nn_accuracy"]]
    assert "--quick" in saved["command"] and "environment" in saved


def test_train_frozen_features_device_error(capsys: pytest.CaptureFixture[str]) -> None:
    """A CUDA device without CUDA, or a malformed one, exits 2 naming --device."""
    module = load("train_frozen_features")
    bad = ["--device", "gpu0"] if torch.cuda.is_available() else ["--device", "cuda"]
    with pytest.raises(SystemExit) as info:
        module.main(bad)
    assert info.value.code == 2 and "--device" in capsys.readouterr().err


@pytest.mark.coil
def test_warp_augmentation(coil_root: Path) -> None:
    result = load("warp_augmentation").main(["--root", str(coil_root), "--quick"])
    assert result["identity_err"] < 1e-4
    # Synthesized at a real view's angle, within 10 % of the nearer seed view copied: the
    # quick run's second step is at alpha (a seed itself), its first 10 degrees past it.
    assert result["worst_gap"] <= 1.1 * result["worst_seed_gap"] + 1e-3


@pytest.mark.coil
@pytest.mark.slow
def test_reject_unknown(coil_root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = load("reject_unknown").main(
        ["--root", str(coil_root), "--known", "1", "2", "3", "--unknown", "11", "12"]
    )
    out = capsys.readouterr().out
    assert "calibrated:" in out and out.count("ROC: known rejected <=") == 4
    roc = result["roc"]
    assert isinstance(roc, list) and roc[0]["unknown_rejected"] >= roc[-1]["unknown_rejected"] == 0.0
    assert all(a["known_rejected"] >= b["known_rejected"] for a, b in itertools.pairwise(roc))
    assert result["n_known"] == 3 * 19 and result["n_unknown"] == 2 * 19
    assert float(result["unknown_rejected"]) > float(result["known_rejected"])  # type: ignore[arg-type]


@pytest.mark.slow
def test_own_photos_small_case() -> None:
    """Every kind of file (8-bit, 16-bit, RGBA, masks given or estimated) fitted in Python,
    saved, loaded and predicted on the views other than the seeds."""
    rows = load("own_photos").main(["--objects", "head", "cylinder", "--test", "-10", "20", "--step", "5"])
    assert [r["kind"] for r in rows] == ["black", "masks", "estimated", "16-bit", "rgba"]
    black = rows[0]["accuracy"]
    assert all(r["n_test"] == 10 and abs(r["accuracy"] - black) <= 100 / 10 for r in rows)  # within one view
    assert black >= 90.0
