"""The thread policy: a context manager that restores the caller's settings, and a library
that never changes them."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import torch_eigview._tuning as _tuning
from torch_eigview.scale import default_threads, thread_policy, threads
from torch_eigview.synthesis import synthesize_views


def test_threads_sets_and_restores() -> None:
    before = torch.get_num_threads()
    with threads(1) as n:
        assert n == 1 and torch.get_num_threads() == 1
        with threads(2) as m:  # nested: the inner setting, then the outer one again
            assert m == 2 and torch.get_num_threads() == 2
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == before


def test_threads_restores_after_an_error() -> None:
    before = torch.get_num_threads()
    with pytest.raises(RuntimeError, match="inside"), threads(2):
        raise RuntimeError("inside")
    assert torch.get_num_threads() == before


def test_threads_limits_blas_pools_and_restores_them() -> None:
    threadpoolctl = pytest.importorskip("threadpoolctl")
    before = [p["num_threads"] for p in threadpoolctl.threadpool_info()]
    with threads(1):
        assert all(p["num_threads"] == 1 for p in threadpoolctl.threadpool_info())
    assert [p["num_threads"] for p in threadpoolctl.threadpool_info()] == before


def test_default_is_the_policy() -> None:
    with threads() as n:
        assert n == default_threads() == 1 == torch.get_num_threads()


@pytest.mark.parametrize(
    ("bad", "kind"), [(0, ValueError), (-2, ValueError), (1.5, TypeError), (True, TypeError)]
)
def test_threads_rejects_bad_counts(bad: object, kind: type[Exception]) -> None:
    before = torch.get_num_threads()
    with pytest.raises(kind, match="threads"), threads(bad):  # type: ignore[arg-type]
        pass
    assert torch.get_num_threads() == before


def test_library_leaves_thread_settings_alone() -> None:
    with threads(2):
        seeds = torch.rand(2, 1, 16, 16, generator=torch.Generator().manual_seed(0))
        synthesize_views(seeds, 5.0, [0.0, 2.5])
        assert torch.get_num_threads() == 2


def _stat(path: Path, cpu0: tuple[int, int], cpu1: tuple[int, int]) -> None:
    """A /proc/stat with (busy, idle) ticks per CPU (busy as user time)."""
    lines = [f"cpu {cpu0[0] + cpu1[0]} 0 0 {cpu0[1] + cpu1[1]} 0 0 0 0 0 0"]
    lines += [f"cpu{i} {busy} 0 0 {idle} 0 0 0 0 0 0" for i, (busy, idle) in enumerate((cpu0, cpu1))]
    path.write_text("\n".join([*lines, "intr 0", ""]))


@pytest.mark.parametrize(
    ("cpu0", "cpu1", "idle", "n"),
    [((100, 120), (120, 100), 1.0, 1), ((100, 120), (100, 120), 2.0, 2), ((120, 100), (120, 100), 0.0, 1)],
)
def test_idle_cpus_and_product_threads_read_the_kernel_counters(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    cpu0: tuple[int, int],
    cpu1: tuple[int, int],
    idle: float,
    n: int,
) -> None:
    stat = tmp_path / "stat"
    _stat(stat, (100, 100), (100, 100))
    # Over the sample each CPU goes from (100 busy, 100 idle) ticks to cpu0 / cpu1.
    monkeypatch.setattr(thread_policy, "allowed_cpus", lambda: [0, 1])
    monkeypatch.setattr(thread_policy.time, "sleep", lambda _: _stat(stat, cpu0, cpu1))
    assert thread_policy.idle_cpus(0.01, stat=stat) == pytest.approx(idle)
    monkeypatch.setattr(thread_policy, "idle_cpus", lambda interval: idle)
    assert thread_policy.product_threads() == n


def test_idle_cpus_without_kernel_counters_counts_every_cpu(tmp_path: Path) -> None:
    assert thread_policy.idle_cpus(0.01, stat=tmp_path / "missing") == len(thread_policy.allowed_cpus())
    with pytest.raises(ValueError, match="interval"):
        thread_policy.idle_cpus(0.0)


def test_for_products_only_inside_the_policy_and_for_large_products(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(thread_policy, "product_threads", lambda: 2)
    big = _tuning.PRODUCT_FLOPS
    with threads(), thread_policy.for_products(big) as n:  # the policy: the idle CPUs
        assert n == 2 == torch.get_num_threads()
    with threads(1), thread_policy.for_products(big) as n:  # --threads 1: left as it is
        assert n == 1 == torch.get_num_threads()
    with threads(), thread_policy.for_products(big / 10) as n:  # small: one thread, no sampling
        assert n == 1 == torch.get_num_threads()
    before = torch.get_num_threads()
    with thread_policy.for_products(big) as n:  # library use, no policy: untouched
        assert n == before == torch.get_num_threads()
