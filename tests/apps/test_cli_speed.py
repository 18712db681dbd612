"""``--threads`` and ``--device`` of the ``eigview`` commands, and the CUDA run's host copies."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest
import torch

from torch_eigview.apps.cli import main

from tests.apps.test_cli import _exit_status

SMALL = [
    "--alpha",
    "10",
    "--synth",
    "-5",
    "10",
    "5",
    "--test",
    "-10",
    "10",
    "--objects",
    "1-2",
    "--components",
    "3",
]


@pytest.mark.parametrize("value", ["0", "-1", "two", "1.5"])
def test_bad_threads(value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, err = _exit_status(["coil", "--folder", str(tmp_path), "--alpha", "10", "--threads", value], capsys)
    assert code == 2 and "--threads must be an integer >= 1" in err and repr(value) in err


@pytest.mark.skipif(torch.cuda.is_available(), reason="the error is for a machine without CUDA")
def test_device_cuda_without_a_gpu(coil_root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, err = _exit_status(["coil", "--folder", str(coil_root), *SMALL, "--device", "cuda"], capsys)
    assert code == 2 and "--device cuda" in err and "is_available() is False" in err


@pytest.mark.slow
def test_threads_applied_in_the_command_and_restored(
    coil_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import torch_eigview.scale.galleries as experiment  # where the gallery synthesis runs

    seen: list[int] = []
    original = experiment.synthesize_views

    def spy(*args: object, **kwargs: object) -> object:
        seen.append(torch.get_num_threads())
        return original(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(experiment, "synthesize_views", spy)
    before = torch.get_num_threads()
    for flag, expected in (([], 1), (["--threads", "2"], 2)):
        seen.clear()
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["coil", "--folder", str(coil_root), *SMALL, "--quiet", *flag]) == 0
        assert seen and set(seen) == {expected}
        assert torch.get_num_threads() == before


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA not available")
def test_cuda_run_matches_cpu_and_counts_host_copies(coil_root: Path) -> None:
    """On CUDA the views, the TV-L1 flow (torch), the warp, eigenspace and recognition run on
    the device; the profiler counts the device-to-host copies of the run. No image goes to
    the host; what remains are scalar reads (the flow's input checks, the maps' branch and
    stopping tests), a few per object and seed pair, not per view."""
    from torch.profiler import ProfilerActivity, profile

    cpu, gpu = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(cpu):
        main(["coil", "--folder", str(coil_root), *SMALL, "--quiet"])
    with (
        profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof,
        contextlib.redirect_stdout(gpu),
    ):
        main(["coil", "--folder", str(coil_root), *SMALL, "--quiet", "--device", "cuda"])
    d2h = sum(e.count for e in prof.key_averages() if "DtoH" in e.key or "Device -> Host" in e.key)
    assert cpu.getvalue().splitlines()[-3] == gpu.getvalue().splitlines()[-3]  # the total accuracy line
    n_views = 2 * 4  # two objects, four synthesized views each
    assert d2h < 40 * n_views, f"{d2h} device-to-host copies"
