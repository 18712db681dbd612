"""The paper's scripts (``examples/paper``) and the diagnoses run at quick settings and write
records ``docs/make_pages.py`` can render; without the COIL images they say where those go."""

from __future__ import annotations

import importlib
import json
from pathlib import Path
from typing import Any

import pytest
import torch

from torch_eigview import CoilFolder, SynthesisOptions
from torch_eigview.synthesis import seed_pair_poses

EXAMPLES = Path(__file__).resolve().parents[1]
COIL_SCRIPTS = [
    "coil20_recognition",
    "every_center",
    "full_circle",
    "onnx_parity",
    "pose_pair_choice",
    "diagnose_flow",
    "diagnose_views",
    "diagnose_chained",
]


def check_record(path: Path, script: str) -> dict[str, Any]:
    """The record at ``path`` in docs/make_pages.py's format, written by ``script``."""
    record = json.loads(path.read_text(encoding="utf-8"))
    assert {"title", "page", "command", "environment", "tables"} <= set(record)
    assert record["page"] == "results" and record["environment"]["packages"]["torch_eigview"]
    assert record["command"].startswith(f"python examples/{script}.py ")
    for table in record["tables"]:
        assert table["caption"] and table["rows"]
        assert all(len(row) == len(table["columns"]) for row in table["rows"]), table
    return record


@pytest.mark.parametrize("name", COIL_SCRIPTS)
def test_missing_data_says_where(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without the images a COIL script exits 2 naming the folder, the variable and the flag."""
    monkeypatch.setenv("TORCH_EIGVIEW_DATA", str(tmp_path))
    main = importlib.import_module(name).main
    with pytest.raises(SystemExit) as info:
        main(["--record", ""])
    err = capsys.readouterr().err
    assert info.value.code == 2
    assert str(tmp_path / "coil-20-proc") in err and "TORCH_EIGVIEW_DATA" in err and "--root" in err
    with pytest.raises(SystemExit) as info:
        main(["--root", str(tmp_path / "nope"), "--record", ""])
    assert info.value.code == 2 and "must be an existing directory" in capsys.readouterr().err


def test_coil20_recognition(coil_root: Path, tmp_path: Path) -> None:
    import coil20_recognition

    argv = [
        "--root",
        str(coil_root),
        "--objects",
        "1,3",
        "--alphas",
        "10",
        "--methods",
        "nvs",
        "dense",
        "nvs3",
    ]
    results = coil20_recognition.main([*argv, "--range-alphas", "10", "--record", str(tmp_path / "r.json")])
    record = check_record(tmp_path / "r.json", "paper/coil20_recognition")
    two, three, around = record["tables"]
    assert two["columns"] == ["α", "paper", "nvs", "dense"] and two["rows"][0][:2] == [10.0, 93.42]
    assert three["rows"][0] == [10.0, results["nvs@10"]["accuracy"], results["nvs3@10"]["accuracy"]]
    # The range table's −20..20 runs are the first table's: run once, the same figures.
    assert around["rows"][0][1].startswith(f"{results['nvs@10']['accuracy']:.2f} (")


def test_every_center(coil_root: Path, tmp_path: Path) -> None:
    import every_center

    argv = ["--root", str(coil_root), "--objects", "1,3", "--centers", "0", "90", "--alphas", "10"]
    out = every_center.main(
        [*argv, "--flows", "guided", "tvl1", "--components", "3", "--record", str(tmp_path / "r.json")]
    )
    record = check_record(tmp_path / "r.json", "paper/every_center")
    per_center, flows = record["tables"]
    assert [row[0] for row in per_center["rows"]] == [0.0, 90.0]
    # The flows table's α = 10 rows are the per-center table's runs.
    assert flows["rows"][0][2:4] == [row[1] for row in per_center["rows"]]
    assert set(out["misses"]) == {"0", "90"}  # type: ignore[arg-type]


def test_full_circle(coil_root: Path, tmp_path: Path) -> None:
    import full_circle

    argv = ["--root", str(coil_root), "--objects", "3", "--seeds", "4", "--step", "30", "--components", "3"]
    full_circle.main([*argv, "--flows", "guided", "--no-defaults", "--record", str(tmp_path / "r.json")])
    record = check_record(tmp_path / "r.json", "paper/full_circle")
    (table,) = record["tables"]
    m, nvs, sparse, dense, n_dense, _ = table["rows"][0]
    assert m == 4 and n_dense == 8 and all(0 <= v <= 100 for v in (nvs, sparse, dense))


def test_onnx_parity(coil_root: Path, tmp_path: Path) -> None:
    import onnx_parity

    pytest.importorskip("onnxruntime")
    out = onnx_parity.main(
        ["--root", str(coil_root), "--objects", "1,2", "--record", str(tmp_path / "r.json")]
    )
    assert out["n"] == 2 * 19 and out["label_agreement"] == 1.0 and out["max_rel_err"] < 1e-4
    check_record(tmp_path / "r.json", "paper/onnx_parity")


def test_reconstruction_error(tmp_path: Path) -> None:
    import reconstruction_error

    (row,) = reconstruction_error.main(["--subsets", "6", "--record", str(tmp_path / "r.json")])
    assert row["interpolated"] < row["sparse"]
    record = check_record(tmp_path / "r.json", "paper/reconstruction_error")
    assert record["tables"][0]["rows"][0][-2:] == [723.3, 534.4]  # the paper's, at N = 6


def test_synthetic_recognition(tmp_path: Path) -> None:
    import synthetic_recognition

    argv = ["--size", "24", "--alphas", "10", "--views", "2", "--shapes", "egg,head", "--test", "-10", "10"]
    results = synthetic_recognition.main([*argv, "--record", str(tmp_path / "r.json")])
    assert [r["correspondences"] for r in results] == ["flow", "exact", "rendered"]
    record = check_record(tmp_path / "r.json", "paper/synthetic_recognition")
    assert record["tables"][0]["rows"] == [[10.0, 2, 100.0, *(r["accuracy"] for r in results)]]


def test_pose_pair_choice(coil_root: Path, tmp_path: Path) -> None:
    """The script's copy of the pair rule gives the library's poses (seed_pair_poses on the
    same views and appearance poses)."""
    import pose_pair_choice

    argv = ["--root", str(coil_root), "--objects", "1", "--seeds", "4", "--every", "17"]
    result = pose_pair_choice.main([*argv, "--record", str(tmp_path / "r.json")])
    records, seeds = result["records"], result["seeds"]
    assert len(records) == 4  # 68 test poses of object 1, every 17th; one object: all recognized
    folder = CoilFolder(coil_root)
    views = folder.images(1, [(seeds[0] + t) % 360 for t, _, _ in records])
    rough = torch.tensor([seeds[0] + r for _, r, _ in records], dtype=torch.float64)
    poses = seed_pair_poses(
        views, rough, folder.images(1, seeds), seeds, closed=True, options=SynthesisOptions()
    )
    diff = (poses - torch.tensor(result["library_poses"], dtype=torch.float64) + 180) % 360 - 180
    assert diff.abs().max() < 1e-6
    assert {"library", "true sector (oracle)", "appearance"} <= set(result["rules"])
    check_record(tmp_path / "r.json", "paper/pose_pair_choice")
