"""ViewCache: a disk-backed, re-generable block source with one block in memory."""

from __future__ import annotations

import os

import pytest
import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.streaming import StreamingEigenspace
from torch_eigview.scale.view_cache import ViewCache


def _blocks() -> list[torch.Tensor]:
    gen = torch.Generator().manual_seed(0)
    basis = torch.rand(6, 2 * 9 * 7, generator=gen)
    return [(torch.rand(n, 6, generator=gen) @ basis).view(n, 2, 9, 7) for n in (5, 8, 3)]


def test_round_trip_and_repeatable() -> None:
    blocks = _blocks()
    with ViewCache() as cache:
        for b in blocks:
            cache.append(b)
        assert cache.n_views == 16 and os.path.getsize(cache.path) == 16 * 2 * 9 * 7 * 4
        for _ in range(2):  # every call reads the same blocks again
            back = list(cache())
            assert [b.shape for b in back] == [b.shape for b in blocks]
            for got, want in zip(back, blocks, strict=True):
                assert torch.equal(got, want)
        path = cache.path
    assert not os.path.exists(path)


def test_float16_storage_rounds_views() -> None:
    blocks = _blocks()
    with ViewCache(dtype=torch.float16) as cache:
        cache.append(blocks[0] / blocks[0].max())
        (got,) = list(cache())
        assert got.dtype == torch.float32
        torch.testing.assert_close(got, blocks[0] / blocks[0].max(), rtol=0, atol=1e-3)
        assert os.path.getsize(cache.path) == 5 * 2 * 9 * 7 * 2


def test_streaming_fit_from_the_cache_equals_explicit_fit() -> None:
    blocks = _blocks()
    with ViewCache() as cache:
        for b in blocks:
            cache.append(b)
        stream = StreamingEigenspace(4, method="exact", max_views=6).fit(cache)
    ref = Eigenspace(4).fit(torch.cat(blocks).flatten(1))
    torch.testing.assert_close(stream.mean_, ref.mean_, rtol=0, atol=1e-6)
    torch.testing.assert_close(stream.eigenvalues_, ref.eigenvalues_, rtol=1e-4, atol=1e-6)
    s = torch.linalg.svdvals(stream.components_.double() @ ref.components_.double().T)
    assert float(s.min()) > 1 - 1e-6
    assert stream.n_passes_ > 1  # the panels re-read the cache


def test_bad_input() -> None:
    with ViewCache() as cache:
        cache.append(torch.rand(2, 1, 4, 4))
        with pytest.raises(
            ValueError, match=r"views must have the view shape of the first block \(1, 4, 4\)"
        ):
            cache.append(torch.rand(2, 1, 4, 5))
        with pytest.raises(ValueError, match=r"views \(as torch.float32\) must be finite"):
            cache.append(torch.full((1, 1, 4, 4), float("nan")))
        with pytest.raises(ValueError, match=r"P_i >= 1"):
            cache.append(torch.rand(0, 1, 4, 4))
        with pytest.raises(TypeError, match=r"views must have a floating dtype"):
            cache.append(torch.ones(2, 1, 4, 4, dtype=torch.int64))
    with pytest.raises(ValueError, match=r"dtype must be one of"):
        ViewCache(dtype=torch.int8)


def test_bench_pipeline_case_runs() -> None:
    """The benchmark's whole-build case (flow + synthesis into the cache, exact Gram from it)."""
    from torch_eigview.apps.bench_scaling import run_case

    row = run_case({"kind": "pipeline", "objects": 3, "size": 32, "channels": 3, "k": 3, "max_views": 41})
    assert row["passes"] > 1 and 0 < row["synthesis_s"] <= row["seconds"]


def test_closed_cache_and_float16_overflow() -> None:
    cache = ViewCache(dtype=torch.float16)
    with pytest.raises(ValueError, match=r"views \(as torch.float16\) must be finite"):
        cache.append(torch.full((1, 1, 2, 2), 1e5))  # finite in float32, inf in float16
    path = cache.path
    cache.close()
    assert not os.path.exists(path)
    with pytest.raises(ValueError, match="closed ViewCache"):
        cache.append(torch.rand(1, 1, 2, 2))
    assert not os.path.exists(path)


def test_file_removed_without_close() -> None:
    import gc

    cache = ViewCache()
    cache.append(torch.rand(2, 1, 3, 3))
    path = cache.path
    del cache
    gc.collect()
    assert not os.path.exists(path)
