"""Every benchmark imports, refuses bad input before any work, and runs in its quick mode.

The quick runs write their records to a temporary folder, checked as ``docs/make_pages.py``
reads them; the slow benchmarks' measuring functions run at a tiny size instead.
"""

from __future__ import annotations

import importlib
import re
import socket
from functools import partial
from pathlib import Path
from types import ModuleType

import pytest
import torch

from benchmarks.tests.test_record import check_record

BENCHMARKS = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(p.stem for p in BENCHMARKS.glob("bench_*.py"))
COIL_SCRIPTS = ["bench_correspondence", "bench_eigen_solver", "bench_stages", "bench_synthesis"]


def load(name: str) -> ModuleType:
    return importlib.import_module(f"benchmarks.{name}")


@pytest.mark.parametrize("name", SCRIPTS)
def test_script_imports_and_has_main(name: str) -> None:
    module = load(name)
    assert callable(getattr(module, "main", None)), f"{name}.py has no main()"
    assert "python benchmarks/" in (module.__doc__ or "") or "benchmarks/bench_" in (module.__doc__ or "")


@pytest.mark.parametrize("name", COIL_SCRIPTS)
def test_missing_data_says_where(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without the images a COIL benchmark exits 2 naming the folder, the variable and the flag."""
    monkeypatch.setenv("TORCH_EIGVIEW_DATA", str(tmp_path))
    with pytest.raises(SystemExit) as info:
        load(name).main(["--quick"])
    err = capsys.readouterr().err
    assert info.value.code == 2
    assert str(tmp_path / "coil-20-proc") in err and "TORCH_EIGVIEW_DATA" in err and "--root" in err
    with pytest.raises(SystemExit) as info:
        load(name).main(["--quick", "--root", str(tmp_path / "nope")])
    assert info.value.code == 2 and "must be an existing directory" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("name", "argv", "message"),
    [
        (
            "bench_eigen",
            ["--root", "{tmp}/none"],
            r"--root='.*none' is not an existing folder of COIL-20 images",
        ),
        ("bench_threads", ["--root", "{tmp}/none"], r"--root='.*none' is not an existing folder"),
        ("bench_warp", ["--threads", "0"], r"--threads must be an integer >= 1, got '0'"),
        ("bench_scaling", ["--png", "{tmp}"], r"--png='.*' is a directory"),
        ("bench_augmentation", ["--out", "{tmp}"], r"--out='.*' is a directory"),
    ],
    ids=["eigen-root-missing", "threads-root-missing", "warp-threads-0", "scaling-png-dir", "out-dir"],
)
def test_bad_input_exits_2_with_a_message(
    name: str, argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as info:
        load(name).main([a.format(tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert info.value.code == 2 and f"python benchmarks/{name}.py: error:" in err
    assert "Traceback" not in err and re.search(message, err), err


def test_warp_quick(tmp_path: Path) -> None:
    out = tmp_path / "warp.json"
    rows = load("bench_warp").main(["--quick", "--out", str(out)])["rows"]
    assert [r["size"] for r in rows] == [32, 64]
    assert all(r["max_diff_sparse"] < 1e-4 and r["max_diff_skimage"] < 1e-4 for r in rows)
    record = check_record(out)
    assert record["tables"][0]["rows"][0][5] == pytest.approx(rows[0]["sparse_views_s"] / rows[0]["kornia_s"])


def test_eigen_step_against_the_references() -> None:
    bench = load("bench_eigen")
    x, what = bench.gallery_matrix(None, quick=True)
    assert x.shape == (205, 4096) and "random smooth views" in what
    e = bench.bench_eigen(x[:60, :256].contiguous(), 5, repeats=1)
    assert e["angle_sklearn_full"] < 1e-3 and e["ours_s"] > 0 and e["pca_lowrank_s"] > 0
    assert bench.bench_gemm(64, 1)["gflops"] > 0


def test_augmentation_quick(tmp_path: Path) -> None:
    out = tmp_path / "augmentation.json"
    result = load("bench_augmentation").main(["--quick", "--out", str(out)])
    assert result["max_diff"] < 1e-5 and result["ratio"] == pytest.approx(
        result["loop_s"] / result["batched_s"]
    )
    check_record(out)


@pytest.mark.skipif(torch.cuda.is_available(), reason="the CPU fallback runs without a GPU")
def test_cuda_without_a_gpu_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cuda.json"
    c = load("bench_cuda").main(["--quick", "--out", str(out)])
    assert c["device"] == "cpu" and c["views_per_s"] > 0 and c["build_s"] > 0
    assert "not measured: no GPU" in capsys.readouterr().out
    assert "not measured: no GPU" in check_record(out)["notes"]


@pytest.mark.slow
def test_predict_memory_quick(tmp_path: Path) -> None:
    """One count in its own predict process (the export is most of this test's time)."""
    out = tmp_path / "predict_memory.json"
    peaks = load("bench_predict_memory").main(["--quick", "--counts", "3", "--out", str(out)])["peak_mib"]
    assert set(peaks) == {3} and peaks[3] > 0
    check_record(out)


def test_projection_agrees_with_pca(monkeypatch: pytest.MonkeyPatch) -> None:
    """One small case of every method (the script raises where one disagrees with PCA.transform)."""
    module = load("bench_projection")
    monkeypatch.setattr(module, "export_projection", partial(module.export_projection, dynamo=False))
    rows = module.bench_projection([4], [2], threads=1, budget=0.001, backend="eager")
    assert set(rows[0]["images_per_s"]) == {"eager", "compile", "ort-plain", "ort", "sklearn"}


def _fake_case(spec: dict[str, object]) -> dict[str, object]:
    """What ``_fit_case.measure`` returns, without the subprocess."""
    out = {**spec, "seconds": 1.0 + len(str(spec["kind"])), "peak_mib": 10.0, "workers_peak_mib": 0.0}
    out.update(passes=1, eigen_threads=1, data_matrix_mib=1.0, gram_mib=1.0, held_mib=0.5, synthesis_s=0.5)
    return out


@pytest.mark.parametrize("name", ["bench_scaling", "bench_coil100"])
def test_tables_of_the_subprocess_benchmarks(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The records of the benchmarks whose every case is a fresh process (measured apart in
    test_fit_case.py), with the cases faked."""
    module = load(name)
    monkeypatch.setattr(module, "measure", _fake_case)
    out = tmp_path / f"{name}.json"
    module.main(["--quick", "--out", str(out)])
    record = check_record(out)
    assert all(row[3] >= 0 for t in record["tables"] for row in t["rows"] if isinstance(row[3], float))


def test_distributed_one_rank(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The torchrun entry as one rank in this process (the environment torchrun would set)."""
    import torch.distributed as dist

    from torch_eigview.io.checkpoint import load_state_dict

    if not dist.is_available():
        pytest.skip("torch.distributed not available")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    for key, value in {
        "MASTER_ADDR": "127.0.0.1",
        "MASTER_PORT": str(port),
        "RANK": "0",
        "WORLD_SIZE": "1",
    }.items():
        monkeypatch.setenv(key, value)
    out, save = tmp_path / "distributed.json", tmp_path / "projection.pt"
    summary = load("bench_distributed").main(["--quick", "--out", str(out), "--save", str(save)])
    assert summary is not None and summary["n_views"] == 4 * 41 and summary["world_size"] == 1
    assert check_record(out)["command"].startswith("torchrun --nproc_per_node 1 ")
    assert load_state_dict(save)["components"].shape == (15, 32 * 32)


@pytest.mark.coil
def test_stages_of_a_coil_run(coil_root: Path) -> None:
    bench = load("bench_stages")
    s = bench.bench_stages(coil_root, [1])
    assert s["maps_s"] > 0 and s["warp_s"] > 0
    assert {"correspondence", "synthesis", "eigen", "recognition", "total"} <= set(s["seconds"])
    assert bench.stages_table(s)["rows"][-1][0].strip().startswith("warp")


@pytest.mark.coil
def test_correspondence_quick(coil_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "correspondence.json"
    result = load("bench_correspondence").main(["--quick", "--root", str(coil_root), "--out", str(out)])
    assert set(result["seconds_per_pair"]["20"]) == {"guided", "tvl1", "tvl1-skimage", "rows"}
    assert all(v > 0 for v in result["seconds_per_pair"]["20"].values())
    check_record(out)


@pytest.mark.coil
def test_eigen_solver_quick(coil_root: Path, tmp_path: Path) -> None:
    """Three objects make 864 views, below SUBSPACE_MIN: "auto" runs the Gram path, and
    both fits are one eigenspace."""
    out = tmp_path / "eigen_solver.json"
    result = load("bench_eigen_solver").main(["--quick", "--root", str(coil_root), "--out", str(out)])
    assert result["views"] == [4 * 3 * 72, 16384] and result["auto_ran"] == "gram"
    assert result["max_principal_angle_rad"] < 1e-6 and all(result["seconds"]["auto"])
    check_record(out)


@pytest.mark.coil
@pytest.mark.slow
def test_synthesis_quick(coil_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "synthesis.json"
    result = load("bench_synthesis").main(["--quick", "--root", str(coil_root), "--out", str(out)])
    assert result["views"] == 3 * 41 and result["same_views"] and result["same_as_whole_grid"]
    assert result["seconds"]["threads"] > 0 and result["seconds"]["one thread"] > 0
    check_record(out)


@pytest.mark.coil
@pytest.mark.slow
def test_synthesis_framed(coil_root: Path) -> None:
    # A margin round the object: the row band gives the whole grid's views.
    args = ["--root", str(coil_root), "--objects", "2", "--workers", "2", "--frame", "0.5", "--out", ""]
    banded = load("bench_synthesis").main(args)
    assert banded["same_views"] and banded["same_as_whole_grid"]
    assert banded["frame"] == 0.5 and not banded["whole_grid"]
    whole = load("bench_synthesis").main([*args, "--whole-grid"])
    assert whole["same_views"] and whole["same_as_whole_grid"] and whole["whole_grid"]


@pytest.mark.slow
def test_fit_ranks_quick(tmp_path: Path) -> None:
    """Two ranks under torchrun against one process on 4 rendered objects: the same labels."""
    out = tmp_path / "ranks.json"
    result = load("bench_fit_ranks").main(["--quick", "--data", str(tmp_path / "data"), "--out", str(out)])
    check_record(out)
    assert result["agreement"]["same_label"] == 100.0 and result["agreement"]["codes_rel"] <= 1e-5
