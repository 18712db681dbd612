"""The threads benchmark: the neighbour it starts, bounded runs, the table and the verdicts."""

from __future__ import annotations

import time
from functools import partial

import pytest

from benchmarks import bench_threads
from benchmarks.bench_threads import cpu_neighbour, threads_table, verdicts


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
    assert bench_threads.run_command(["demo", "--size", "32", "--png", ""], timeout_s=0.05) is None


def test_a_failing_run_says_why() -> None:
    with pytest.raises(RuntimeError, match=r"eigview coil .* failed"):
        bench_threads.run_command(["coil", "--alpha", "10", "--threads", "0"], timeout_s=60)


def test_a_failing_python_run_names_itself() -> None:
    with pytest.raises(RuntimeError, match=r"(?s)reference: 1 thread failed \(1\): .*ZeroDivisionError"):
        bench_threads.run_python(["-c", "1 / 0"], timeout_s=60, name="reference: 1 thread")


def _result(rows: list[dict[str, object]], refs: list[dict[str, object]] | None = None) -> dict[str, object]:
    out: dict[str, object] = {"command": "coil", "neighbour_procs": 2, "timeout_s": 60.0, "rows": rows}
    if refs is not None:
        out["references"] = refs
    return out


def test_verdicts_and_table() -> None:
    rows = [
        {"setting": "policy (default)", "quiet_s": 10.0, "loaded_s": 12.0, "loaded_over_quiet": 1.2},
        {"setting": "--threads 1", "quiet_s": 10.0, "loaded_s": 12.0, "loaded_over_quiet": 1.2},
        {"setting": "--threads 2", "quiet_s": 8.5, "loaded_s": None, "loaded_over_quiet": None},
    ]
    lines = verdicts(_result(rows))
    assert "policy / best (quiet): 1.18 (target <= 1.3: met)" in lines
    assert "policy loaded / quiet: 1.20 (target <= 1.5: met)" in lines
    assert not any("floor" in line for line in lines)  # no reference rows: no floor line
    t = threads_table(_result(rows))
    assert t["rows"][0][4] == pytest.approx(10 / 8.5) and t["rows"][2][2] is None  # the timed-out run
    assert "past the 60 s timeout" in t["caption"]


def test_verdicts_read_the_policy_against_the_reference() -> None:
    rows = [{"setting": "policy (default)", "quiet_s": 5.0, "loaded_s": 9.0, "loaded_over_quiet": 1.8}]
    refs = [
        {"setting": "reference: 1 thread", "quiet_s": 2.0, "loaded_s": 3.2, "loaded_over_quiet": 1.6},
        {"setting": "reference: 2 threads", "quiet_s": 1.0, "loaded_s": 2.4, "loaded_over_quiet": 2.4},
    ]
    lines = verdicts(_result(rows, refs))
    assert "policy loaded / quiet: 1.80 (target <= 1.5: NOT met)" in lines
    assert lines[-1].endswith("loaded / quiet: 1.60 (1 thread), 2.40 (2 threads)")
    assert [r[0] for r in threads_table(_result(rows, refs))["rows"]][-1] == "reference: 2 threads"


def test_quiet_and_loaded_runs_twice_and_takes_the_ratio() -> None:
    """A row: the run quiet, then beside one spinning process (a bare interpreter here)."""
    run = partial(bench_threads.run_python, ["-c", "pass"], 60.0, "bare")
    row = bench_threads.quiet_and_loaded("bare", run, n_procs=1, timeout_s=60.0)
    assert row["setting"] == "bare" and row["quiet_s"] > 0 and row["loaded_s"] > 0
    assert row["loaded_over_quiet"] == pytest.approx(row["loaded_s"] / row["quiet_s"])


def test_reference_job_is_a_fixed_amount_of_work() -> None:
    """The reference job's code runs (a few products of small matrices, in this process)."""
    code = bench_threads._REFERENCE.format(threads=1, iters=2).replace("512", "8")
    exec(compile(code, "<reference>", "exec"), {})
