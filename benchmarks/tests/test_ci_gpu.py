"""``.ci/gpu``, the GPU checks in one command: refused without CUDA, and its dry run on the CPU."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / ".ci" / "gpu"

pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="the script is a bash script")


def _run(args: list[str], env: dict[str, str], timeout: float) -> subprocess.CompletedProcess[str]:
    # The script calls python3 (else python); this interpreter comes first on PATH.
    path = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return subprocess.run(
        ["bash", str(SCRIPT), *args],
        env={**env, "PATH": path, "OMP_NUM_THREADS": "1"},
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


@pytest.mark.skipif(torch.cuda.is_available(), reason="the refusal is for a machine without CUDA")
def test_refuses_without_cuda(tmp_path: Path) -> None:
    done = _run([str(tmp_path / "out")], dict(os.environ), timeout=120)
    assert done.returncode == 2
    assert "torch.cuda.is_available() is False" in done.stderr and "--cpu" in done.stderr
    assert not (tmp_path / "out" / "gpu_bench.json").exists()


@pytest.mark.slow
def test_cpu_dry_run_writes_its_logs_and_reads_the_data_variable(tmp_path: Path) -> None:
    """``--cpu``: the CUDA tests skip, the benchmark prints its CPU fallback, everything lands
    in OUT_DIR; ``TORCH_EIGVIEW_DATA`` steers the tests' COIL folder (here one without it)."""
    out, data = tmp_path / "out", tmp_path / "data"
    data.mkdir()
    env = {**os.environ, "TORCH_EIGVIEW_DATA": str(data)}
    env.pop("OUT", None)
    done = _run(["--cpu", str(out)], env, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    tests_log = (out / "gpu_tests.log").read_text()
    assert " skipped" in tests_log and "CUDA not available" in tests_log  # the CUDA tests skip cleanly
    assert f"COIL-20 not found at {data / 'coil-20-proc'}" in tests_log  # the variable, not ../shared
    bench = json.loads((out / "gpu_bench.json").read_text())  # the benchmark's result record
    assert bench["page"] == "benchmarks" and "python benchmarks/bench_cuda.py --out" in bench["command"]
    assert bench["raw"]["device"] == "cpu" and bench["raw"]["build_s"] > 0
    assert "not measured: no GPU" in (out / "gpu_bench.log").read_text()
