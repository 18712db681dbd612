"""``eigview fit`` under ``torchrun --nproc-per-node 2`` (issue 39: scale-out): the objects
split over two gloo ranks give the model of one process, the gallery held and merged
(``--max-views`` below the gallery): coefficients within 1e-5 relative (each rank runs its
share of the CPUs' threads, so float32 products may round apart); rank 0 alone writes and
reports."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import torch.distributed as dist

from torch_eigview.io.checkpoint import load_recognizer

from tests.adversarial import views

pytestmark = pytest.mark.skipif(not dist.is_available(), reason="torch.distributed not available")

FIT = ("--seeds", "0", "10", "--synth", "-10", "20", "2", "-k", "4", "--quiet")


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _fit(tmp: Path, out: str, ranks: int, *flags: str) -> subprocess.CompletedProcess[str]:
    launcher = (
        [
            sys.executable,
            "-m",
            "torch.distributed.run",
            "--nproc-per-node",
            str(ranks),
            "--master-port",
            str(_port()),
        ]
        if ranks > 1
        else [sys.executable]
    )
    argv = [*launcher, "-m", "torch_eigview", "fit", "--manifest", "views.csv", *FIT, *flags, "--out", out]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run(argv, cwd=tmp, capture_output=True, text=True, timeout=300, env=env)


def _relative(got: torch.Tensor, want: torch.Tensor) -> float:
    finite = torch.isfinite(want)
    assert torch.equal(torch.isfinite(got), finite) and torch.equal(got[~finite], want[~finite])
    return float((got[finite] - want[finite]).abs().max()) / float(want[finite].abs().max())


@pytest.mark.slow
@pytest.mark.parametrize(
    ("flags", "rtol"), [((), 1e-5), (("--max-views", "20"), 1e-5)], ids=["held", "merged"]
)
def test_two_ranks_write_the_model_of_one_process(
    tmp_path: Path, flags: tuple[str, ...], rtol: float
) -> None:
    views.manifest(tmp_path)
    one = _fit(tmp_path, "one.pt", 1, *flags)
    two = _fit(tmp_path, "two.pt", 2, *flags)
    assert one.returncode == 0, one.stderr
    assert two.returncode == 0, two.stderr
    assert two.stdout.count("wrote two.pt: 2 objects") == 1, two.stdout  # rank 0 alone reports
    a, _ = load_recognizer(tmp_path / "one.pt")
    b, _ = load_recognizer(tmp_path / "two.pt")
    assert torch.equal(a.labels, b.labels) and torch.equal(a.poses, b.poses)
    assert a.label_names == b.label_names
    for got, want in ((b.codes, a.codes), (b.projection.components, a.projection.components)):
        assert _relative(got, want) <= rtol
    assert _relative(b.reject_thresholds, a.reject_thresholds) <= max(rtol, 1e-6)
