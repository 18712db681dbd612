"""The examples run (quick settings), so they cannot rot; every script at least imports."""

from __future__ import annotations

import importlib.util
import itertools
from pathlib import Path
from types import ModuleType

import pytest

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
    "bench_correspondence",
    "bench_eigen_solver",
    "bench_synthesis",
    "reject_unknown",
    "coil20_recognition",
    "full_circle",
    "kernel_pca",
    "pose_pair_choice",
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
def test_train_frozen_features(coil_root: Path) -> None:
    # aot_eager: the same torch.compile path (Dynamo + AOTAutograd) without inductor's C++ build.
    result = load("train_frozen_features").main(
        ["--root", str(coil_root), "--quick", "--compile-backend", "aot_eager"]
    )
    assert result["accuracy"] >= 90.0
    assert result["compile_err"] < 1e-4 and result["dtype_err"] < 1e-4


@pytest.mark.coil
def test_bench_correspondence(coil_root: Path) -> None:
    result = load("bench_correspondence").main(["--root", str(coil_root), "--objects", "1", "--alpha", "20"])
    seconds = result["seconds_per_pair"]
    assert set(seconds) == {"guided alpha=20", "tvl1 alpha=20", "tvl1-skimage alpha=20", "rows alpha=20"}
    assert all(v > 0 for v in seconds.values())


@pytest.mark.coil
def test_bench_synthesis(coil_root: Path) -> None:
    result = load("bench_synthesis").main(["--root", str(coil_root), "--objects", "3", "--workers", "2"])
    assert (
        result["views"] == 3 * 41 and result["seconds"]["threads"] > 0 and result["seconds"]["one thread"] > 0
    )
    assert result["same_views"]


@pytest.mark.coil
def test_bench_synthesis_framed(coil_root: Path) -> None:
    # A margin round the object: the row band gives the whole grid's views.
    args = ["--root", str(coil_root), "--objects", "2", "--workers", "2", "--frame", "0.5"]
    banded = load("bench_synthesis").main(args)
    assert banded["same_views"] and banded["same_as_whole_grid"]
    assert banded["frame"] == 0.5 and not banded["whole_grid"]
    whole = load("bench_synthesis").main([*args, "--whole-grid"])
    assert whole["same_views"] and whole["same_as_whole_grid"] and whole["whole_grid"]


@pytest.mark.coil
def test_pose_pair_choice(coil_root: Path) -> None:
    """The script's copy of the pair rule gives the library's poses (seed_pair_poses on the
    same views and appearance poses)."""
    import torch

    from torch_eigview.datasets import CoilFolder
    from torch_eigview.synthesis import SynthesisOptions, seed_pair_poses

    result = load("pose_pair_choice").main(["--root", str(coil_root), "--objects", "1", "--every", "8"])
    records, seeds = result["records"], result["seeds"]
    assert len(records) >= 6  # 8 test poses of object 1, nearly all recognized
    folder = CoilFolder(coil_root)
    views = folder.images(1, [(seeds[0] + t) % 360 for t, _, _ in records])
    rough = torch.tensor([seeds[0] + r for _, r, _ in records], dtype=torch.float64)
    poses = seed_pair_poses(
        views, rough, folder.images(1, seeds), seeds, closed=True, options=SynthesisOptions()
    )
    diff = (poses - torch.tensor(result["library_poses"], dtype=torch.float64) + 180) % 360 - 180
    assert diff.abs().max() < 1e-6
    assert {"library", "true sector (oracle)", "appearance"} <= set(result["rules"])


@pytest.mark.coil
def test_bench_eigen_solver(coil_root: Path) -> None:
    """Three objects make 864 views, below SUBSPACE_MIN: "auto" runs the Gram path, and
    both fits are one eigenspace."""
    result = load("bench_eigen_solver").main(["--root", str(coil_root), "--objects", "3", "--rounds", "1"])
    assert result["views"] == [4 * 3 * 72, 16384] and result["auto_ran"] == "gram"
    assert result["max_principal_angle_rad"] < 1e-6 and all(result["seconds"]["auto"])


@pytest.mark.coil
def test_warp_augmentation(coil_root: Path) -> None:
    result = load("warp_augmentation").main(["--root", str(coil_root), "--quick"])
    assert result["identity_err"] < 1e-4
    assert result["worst_gap"] < 0.05


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
    """Every kind of file (8-bit, 16-bit, RGBA, masks given or estimated) through fit and evaluate."""
    rows = load("own_photos").main(["--objects", "head", "cylinder", "--test", "-10", "20", "--step", "5"])
    assert [r["kind"] for r in rows] == ["black", "masks", "estimated", "16-bit", "rgba"]
    black = rows[0]["accuracy"]
    assert all(r["n_test"] == 14 and abs(r["accuracy"] - black) <= 100 / 14 for r in rows)  # within one view
    assert black >= 90.0
