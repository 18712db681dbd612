"""The examples run (quick settings), so they cannot rot."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.coil
def test_train_frozen_features(coil_root: Path) -> None:
    # aot_eager: the same torch.compile path (Dynamo + AOTAutograd) without inductor's C++ build.
    result = load("train_frozen_features").main(
        ["--root", str(coil_root), "--quick", "--compile-backend", "aot_eager"]
    )
    assert result["accuracy"] >= 90.0
    assert result["compile_err"] < 1e-4 and result["dtype_err"] < 1e-4


@pytest.mark.coil
def test_warp_augmentation(coil_root: Path) -> None:
    result = load("warp_augmentation").main(["--root", str(coil_root), "--quick"])
    assert result["identity_err"] < 1e-4
    assert result["worst_gap"] < 0.05
