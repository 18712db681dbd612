"""The speed sections of ``eigview bench``: the neighbour it starts, bounded runs, the reports."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import torch

from torch_eigview.apps import bench_speed
from torch_eigview.apps.bench_speed import (
    bench_cuda,
    bench_stages,
    cpu_neighbour,
    report_cuda,
    report_threads,
)


def test_neighbour_spins_and_is_killed() -> None:
    with cpu_neighbour(2, limit_s=30.0) as procs:
        assert len(procs) == 2 and all(p.poll() is None for p in procs)
    assert all(p.poll() is not None for p in procs)


def test_neighbour_ends_by_itself() -> None:
    with cpu_neighbour(1, limit_s=0.3) as procs:
        t0 = time.monotonic()
        while procs[0].poll() is None and time.monotonic() - t0 < 20:
            time.sleep(0.05)
        assert procs[0].poll() == 0


def test_a_run_past_its_timeout_is_none() -> None:
    assert bench_speed._run_command(["demo", "--size", "32", "--png", ""], timeout_s=0.05) is None


def test_a_failing_run_says_why() -> None:
    with pytest.raises(RuntimeError, match=r"eigview coil .* failed"):
        bench_speed._run_command(["coil", "--alpha", "10", "--threads", "0"], timeout_s=60)


def test_threads_report_gives_verdicts(capsys: pytest.CaptureFixture[str]) -> None:
    rows = [
        {"setting": "policy (default)", "quiet_s": 10.0, "loaded_s": 12.0, "loaded_over_quiet": 1.2},
        {"setting": "--threads 1", "quiet_s": 10.0, "loaded_s": 12.0, "loaded_over_quiet": 1.2},
        {"setting": "--threads 2", "quiet_s": 8.5, "loaded_s": None, "loaded_over_quiet": None},
    ]
    report_threads({"command": "coil", "neighbour_procs": 2, "timeout_s": 60.0, "rows": rows})
    out = capsys.readouterr().out
    assert "> 60" in out  # the timed-out run
    assert "policy / best (quiet): 1.18 (target <= 1.3: met)" in out
    assert "policy loaded / quiet: 1.20 (target <= 1.5: met)" in out
    assert "floor" not in out  # no reference rows: no floor line


def test_threads_report_reads_the_policy_against_the_reference(capsys: pytest.CaptureFixture[str]) -> None:
    rows = [{"setting": "policy (default)", "quiet_s": 5.0, "loaded_s": 9.0, "loaded_over_quiet": 1.8}]
    refs = [
        {"setting": "reference: 1 thread", "quiet_s": 2.0, "loaded_s": 3.2, "loaded_over_quiet": 1.6},
        {"setting": "reference: 2 threads", "quiet_s": 1.0, "loaded_s": 2.4, "loaded_over_quiet": 2.4},
    ]
    report_threads(
        {"command": "coil", "neighbour_procs": 2, "timeout_s": 60.0, "rows": rows, "references": refs}
    )
    out = capsys.readouterr().out
    assert "reference: 2 threads" in out and "policy loaded / quiet: 1.80 (target <= 1.5: NOT met)" in out
    assert "loaded / quiet: 1.60 (1 thread), 2.40 (2 threads)" in out


def test_reference_job_runs_quiet_and_loaded() -> None:
    """The reference job really runs (a short one), quiet and beside one spinning process."""
    refs = bench_speed._reference_rows(1, timeout_s=60.0, iters=5)
    assert [r["setting"] for r in refs] == ["reference: 1 thread", "reference: 2 threads"]
    for r in refs:
        assert r["quiet_s"] > 0 and r["loaded_s"] > 0
        assert r["loaded_over_quiet"] == pytest.approx(r["loaded_s"] / r["quiet_s"])


def test_a_failing_python_run_names_itself() -> None:
    with pytest.raises(RuntimeError, match=r"(?s)reference: 1 thread failed \(1\): .*ZeroDivisionError"):
        bench_speed._run_python(["-c", "1 / 0"], timeout_s=60, name="reference: 1 thread")


@pytest.mark.slow
def test_stages_of_a_coil_run(coil_root: Path) -> None:
    s = bench_stages(str(coil_root), [1])
    assert s["maps_s"] > 0 and s["warp_s"] > 0
    assert {"correspondence", "synthesis", "eigen", "recognition"} <= set(s["seconds"])


@pytest.mark.slow
@pytest.mark.skipif(torch.cuda.is_available(), reason="the CPU fallback runs without a GPU")
def test_cuda_section_without_a_gpu_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    c = bench_cuda(quick=True)
    assert c["device"] == "cpu" and c["views_per_s"] > 0 and c["build_s"] > 0
    report_cuda(c)
    assert "not measured: no GPU" in capsys.readouterr().out
