"""ViewCache: a disk-backed, re-generable block source with one block in memory."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest
import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.streaming import StreamingEigenspace
from torch_eigview.files import TEMP_MARK
from torch_eigview.scale import view_cache
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
        stream = StreamingEigenspace(4, solver="exact", max_views=6).fit(cache)
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


def _fail_after(limit: int, calls: list[int]) -> object:
    """An ``os.pwrite`` that writes ``limit`` bytes in all, then fails as a file-size limit does."""
    real = os.pwrite

    def pwrite(fd: int, data: memoryview, offset: int) -> int:
        room = limit - sum(calls)
        if room <= 0:
            raise OSError(errno.EFBIG, "File too large")
        calls.append(real(fd, data[:room], offset))
        return calls[-1]

    return pwrite


def test_failed_append_is_rolled_back(monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = _blocks()
    with ViewCache() as cache:
        cache.append(blocks[0])
        size = os.path.getsize(cache.path)
        monkeypatch.setattr(view_cache.os, "pwrite", _fail_after(100, []))
        with pytest.raises(
            OSError, match=r"appending 4032 bytes to ViewCache .* failed .*rolled back to its 1 earlier"
        ):
            cache.append(blocks[1])
        monkeypatch.undo()
        assert os.path.getsize(cache.path) == size and cache.n_views == 5
        cache.append(blocks[2])  # goes where the failed block would have gone
        back = list(cache())
        assert len(back) == 2 and torch.equal(back[0], blocks[0]) and torch.equal(back[1], blocks[2])


def test_cache_that_cannot_roll_back_is_broken(monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = _blocks()
    with ViewCache() as cache:
        cache.append(blocks[0])
        monkeypatch.setattr(view_cache.os, "pwrite", _fail_after(100, []))
        monkeypatch.setattr(
            view_cache.os, "ftruncate", lambda fd, n: (_ for _ in ()).throw(OSError(errno.EIO, "I/O error"))
        )
        with pytest.raises(OSError):
            cache.append(blocks[1])
        monkeypatch.undo()
        with pytest.raises(ValueError, match=r"is broken, views cannot be read from it: an append failed"):
            list(cache())
        with pytest.raises(ValueError, match=r"is broken, views cannot be appended to it"):
            cache.append(blocks[2])


def test_file_changed_outside_the_cache_is_detected() -> None:
    with ViewCache() as cache:
        cache.append(_blocks()[0])
        with open(cache.path, "ab") as fh:
            fh.write(b"\0" * 8)
        with pytest.raises(ValueError, match=r"holds 2528 bytes but 2520 were appended"):
            list(cache())


def test_limits_and_directory_errors(tmp_path: Path) -> None:
    with ViewCache(tmp_path, max_bytes=3000) as cache:
        cache.append(_blocks()[0])  # 2520 bytes
        with pytest.raises(ValueError, match=r"above max_bytes=3000; raise max_bytes"):
            cache.append(_blocks()[0])
        assert cache.n_views == 5 and os.path.getsize(cache.path) == 2520
    with pytest.raises(ValueError, match=r"directory='.*missing' does not exist"):
        ViewCache(tmp_path / "missing")
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match=r"directory='.*file' is not a folder"):
        ViewCache(tmp_path / "file")
    with pytest.raises(TypeError, match=r"directory must be a folder path"):
        ViewCache(3)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"max_bytes=0 must be"):
        ViewCache(tmp_path, max_bytes=0)


def test_leftover_of_a_dead_writer_is_removed_and_a_live_one_kept(tmp_path: Path) -> None:
    stale = tmp_path / f"eigview-views{TEMP_MARK}dead.bin"  # unlocked: its writer is gone
    stale.write_bytes(b"\0" * 64)
    unrelated = tmp_path / "eigview-views-user.bin"
    unrelated.write_bytes(b"keep")
    with ViewCache(tmp_path) as live:
        assert not stale.exists() and unrelated.exists()
        with ViewCache(tmp_path) as other:  # the first cache's file is locked: it stays
            assert os.path.exists(live.path) and os.path.exists(other.path)
    assert sorted(os.listdir(tmp_path)) == ["eigview-views-user.bin"]
