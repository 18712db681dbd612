"""The thread policy: a context manager that restores the caller's settings, and a library
that never changes them."""

from __future__ import annotations

import pytest
import torch

from torch_eigview.scale import default_threads, threads
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
