"""Tests for ``synthesize_objects`` (in-process ``synthesize_views`` as the reference) and ``map_ordered``'s threads."""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterator

import pytest
import torch

import torch_eigview._tuning as _tuning
from torch_eigview.scale.job_warnings import job_warnings
from torch_eigview.scale.parallel import (
    each_or_alone,
    group_size,
    grouped,
    map_ordered,
    synthesize_objects,
)
from torch_eigview.synthesis import SynthesisOptions, synthesize_views

from tests.helpers import smooth_views

THETAS = [-6.0, -2.0, 0.0, 2.5, 5.0, 9.0]


def seeds_of(n: int, size: int = 32) -> list[torch.Tensor]:
    return [smooth_views(o, 6, 3, size)[[0, 5]] for o in range(n)]


@pytest.mark.slow
def test_workers_equal_in_process_in_order() -> None:
    """Two spawned workers give exactly the in-process views, in the input order, for a
    generator input longer than the in-flight window (2 · workers)."""
    seeds = seeds_of(6)
    opts = SynthesisOptions(extent=False)
    out = list(synthesize_objects(iter(seeds), 5.0, THETAS, opts, workers=2))
    assert len(out) == len(seeds)
    for s, got in zip(seeds, out, strict=True):
        ref = synthesize_views(s, 5.0, THETAS, opts)
        assert torch.equal(got.views, ref.views)
        assert torch.equal(got.thetas, ref.thetas) and got.elevations == ref.elevations


def test_in_process_and_tensor_angles() -> None:
    seeds = seeds_of(2)
    out = list(synthesize_objects(seeds, [5.0], torch.tensor(THETAS), workers=0))
    for s, got in zip(seeds, out, strict=True):
        assert torch.equal(got.views, synthesize_views(s, 5.0, THETAS).views)


@pytest.mark.slow
def test_worker_error_reaches_the_caller() -> None:
    """An object's ValueError in a worker is raised here, at that object's turn; the
    objects before it were yielded; nothing hangs."""
    seeds = seeds_of(2)
    bad = seeds[1][:1]  # one view: synthesize_views needs two
    got = []
    with pytest.raises(ValueError, match="at least 2 views"):
        for views in synthesize_objects([seeds[0], bad, seeds[1]], 5.0, THETAS, workers=1):
            got.append(views)
    assert len(got) == 1


@pytest.mark.slow
def test_stopping_early_shuts_the_pool() -> None:
    gen = synthesize_objects(seeds_of(5), 5.0, THETAS, workers=1)
    first = next(gen)
    gen.close()  # the pool is shut down, pending objects are cancelled
    assert first.views.shape == (len(THETAS), 3, 32, 32)


@pytest.mark.parametrize(
    ("workers", "error", "match"),
    [
        (-1, ValueError, r"workers=-1 must be >= 0"),
        (1.5, TypeError, "workers must be an int"),
        (True, TypeError, "workers must be an int"),
    ],
)
def test_bad_workers(workers: object, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        next(synthesize_objects(seeds_of(1), 5.0, THETAS, workers=workers))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("group", "error", "match"),
    [
        (0, ValueError, r"group=0 must be >= 1"),
        (1.5, TypeError, "group must be an int"),
        (True, TypeError, "group must be an int"),
    ],
)
def test_bad_group(group: object, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        next(synthesize_objects(seeds_of(1), 5.0, THETAS, group=group))  # type: ignore[arg-type]


def test_bad_object_type() -> None:
    with pytest.raises(TypeError, match=r"objects must yield \(V, C, H, W\) tensors, got list"):
        next(synthesize_objects([[1.0, 2.0]], 5.0, THETAS, workers=1))  # type: ignore[list-item]


def test_bad_arguments_raise_before_any_process() -> None:
    with pytest.raises(ValueError, match="thetas must be finite"):
        next(synthesize_objects(seeds_of(1), 5.0, [1.0, float("nan")], workers=2))
    with pytest.raises(ValueError, match="at least 2 views"):
        next(synthesize_objects([seeds_of(1)[0][:1]], 5.0, THETAS, workers=2))
    with pytest.raises(TypeError, match="options must be a SynthesisOptions or None, got dict"):
        next(synthesize_objects(seeds_of(1), 5.0, THETAS, {"flow": "ilk"}, workers=2))  # type: ignore[arg-type]
    assert list(synthesize_objects([], 5.0, THETAS, workers=2)) == []


@pytest.mark.slow
def test_shared_memory_stays_with_the_pool() -> None:
    """Seeds are copied before they are sent (sending moves a storage into shared memory,
    the caller's whole tensor with it) and results are copied out of it."""
    big = torch.cat(seeds_of(3))  # (6, 3, 32, 32); the objects are views of it
    objects = [big[2 * i : 2 * i + 2] for i in range(3)]
    out = list(synthesize_objects(objects, 5.0, THETAS, workers=1))
    assert not big.is_shared()
    assert not any(o.views.is_shared() for o in out)


def _job(i: int) -> tuple[int, int, list[str]]:
    """Warns with its own number (after a pause, so that the threads' jobs overlap)."""
    with job_warnings(UserWarning) as caught:
        time.sleep(0.01 * (i % 3))
        warnings.warn(f"job {i}", UserWarning, stacklevel=1)
        if i == 5:
            raise ValueError("job 5 refuses")
    return i, torch.get_num_threads(), [str(w.message) for w in caught]


def test_thread_pool_in_order_with_each_jobs_warnings() -> None:
    before = torch.get_num_threads()
    out = list(map_ordered(_job, [(i,) for i in range(5)], 3, kind="thread", always=(UserWarning,)))
    assert [o[0] for o in out] == list(range(5))
    assert all(o[1] == before for o in out)  # the caller's intra-op threads, unchanged
    assert [o[2] for o in out] == [[f"job {i}"] for i in range(5)]
    with warnings.catch_warnings(record=True) as outside:  # the routing is gone with the pool
        warnings.simplefilter("always")
        warnings.warn("after", UserWarning, stacklevel=1)
    assert [str(w.message) for w in outside] == ["after"]


def test_thread_pool_error_and_bad_kind() -> None:
    with pytest.raises(ValueError, match="job 5 refuses"):
        list(map_ordered(_job, [(i,) for i in range(8)], 2, kind="thread"))
    with pytest.raises(ValueError, match=r"kind='fiber' must be one of \('process', 'thread'\)"):
        list(map_ordered(_job, [(1,)], 2, kind="fiber"))


def test_thread_pools_keep_the_callers_warning_state() -> None:
    """The caller's filters stay in force while a pool is open, pools may close in any
    order, and the handler and filters are the caller's again after both."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the caller's choice
        before = (warnings.showwarning, list(warnings.filters))
        g1 = map_ordered(_job, [(i,) for i in range(3)], 1, kind="thread")
        g2 = map_ordered(_job, [(i,) for i in range(3)], 1, kind="thread", always=(UserWarning,))
        assert next(g1)[2] == [] and next(g2)[2] == ["job 0"]  # g1 names no category: ignored
        with warnings.catch_warnings(record=True) as seen:  # a consumer's own warning
            warnings.warn("consumer", RuntimeWarning, stacklevel=1)
        assert seen == []  # RuntimeWarning is still ignored
        g1.close()
        assert next(g2)[2] == ["job 1"]  # g2's jobs still get their own warnings
        g2.close()
        assert (warnings.showwarning, list(warnings.filters)) == before


def test_nested_job_warnings_keep_the_outer_list() -> None:
    def job() -> list[str]:
        with job_warnings(UserWarning) as outer:
            with job_warnings(UserWarning) as inner:
                warnings.warn("inner", UserWarning, stacklevel=1)
            warnings.warn("after inner", UserWarning, stacklevel=1)
        assert [str(w.message) for w in inner] == ["inner"]
        return [str(w.message) for w in outer]

    assert list(map_ordered(job, [()], 1, kind="thread", always=(UserWarning,))) == [["after inner"]]
    assert job() == ["after inner"]  # the same without a pool


def _jobs_then_error(n: int) -> Iterator[tuple[int]]:
    yield from ((i,) for i in range(n))
    raise FileNotFoundError(f"no job {n}")


@pytest.mark.parametrize("workers", [0, 2, 3])
def test_an_error_reading_the_jobs_comes_after_the_jobs_before_it(workers: int) -> None:
    """As in order: the jobs read before it yield their results, or the first one's error
    (job 5's here), before the error of the jobs' iterable is raised."""
    got: list[int] = []
    with pytest.raises(FileNotFoundError, match="no job 4"):
        for out in map_ordered(_job, _jobs_then_error(4), workers, kind="thread"):
            got.append(out[0])
    assert got == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="job 5 refuses"):
        list(map_ordered(_job, _jobs_then_error(7), workers, kind="thread"))


@pytest.mark.parametrize("limit", [_tuning.GROUP_OBJECTS, 3, 1])
def test_group_size_and_grouped(monkeypatch: pytest.MonkeyPatch, limit: int) -> None:
    """Jobs of at most GROUP_OBJECTS objects (the default or a smaller one), and no more
    jobs than that needs per round of the workers; the grouping reads its items lazily
    and raises a reading error after the group read before it."""
    monkeypatch.setattr(_tuning, "GROUP_OBJECTS", limit)
    for n in range(1, 60):
        for w in range(0, 5):
            size = group_size(n, w)
            slots = max(1, w)
            assert 1 <= size <= limit
            assert -(-n // size) <= slots * -(-n // (slots * limit))
    assert group_size(20, 2) == min(5, limit)  # 20 objects over 2 workers: 4 jobs of 5
    assert list(grouped(range(7), 3)) == [[0, 1, 2], [3, 4, 5], [6]]
    assert list(grouped([], 3)) == []
    got: list[list[int]] = []
    with pytest.raises(FileNotFoundError, match="no job 4"):
        for group in grouped((i for (i,) in _jobs_then_error(4)), 3):
            got.append(group)
    assert got == [[0, 1, 2], [3]]


def test_a_group_gives_each_objects_views_or_its_error() -> None:
    """Objects synthesized as one group (their flows batched) give the views each gives
    alone; an object refused in the middle of a group is an error at its turn."""
    seeds = seeds_of(4)
    alone = [synthesize_views(s, 5.0, THETAS) for s in seeds]
    for got, want in zip(synthesize_objects(seeds, 5.0, THETAS, workers=0), alone, strict=True):
        assert torch.equal(got.views, want.views) and got.elevations == want.elevations
    got = []
    with pytest.raises(ValueError, match="at least 2 views"):
        for views in synthesize_objects([seeds[0], seeds[1], seeds[2][:1], seeds[3]], 5.0, THETAS):
            got.append(views)
    assert [torch.equal(g.views, a.views) for g, a in zip(got, alone, strict=False)] == [True, True]


def test_each_or_alone_keeps_the_jobs_before_a_refusal() -> None:
    """Jobs share what the group computed until one is refused; that one and the later ones
    go alone, the earlier outcomes are kept (not computed again)."""
    calls: list[tuple[int, object]] = []

    def one(job: int, shared: object) -> int | ValueError:
        calls.append((job, shared))
        return ValueError(f"job {job}") if job == 2 and shared is not None else job

    out = each_or_alone([0, 1, 2, 3], "batch", one)
    assert out == [0, 1, 2, 3]
    assert calls == [(0, "batch"), (1, "batch"), (2, "batch"), (2, None), (3, None)]
    assert each_or_alone([5], None, lambda job, shared: ValueError("x"))[0].args == ("x",)
