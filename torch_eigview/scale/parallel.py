"""Synthesis of many objects over worker processes, in order, with bounded memory.

Per object the build is optical flow and the warp maps: many small torch operations,
each too little work to split over OpenMP threads (``torch_eigview._tuning``'s
``THREADS_DEFAULT``). Objects are independent, so the cheap way to use the machine's
cores is one object per process:
:func:`synthesize_objects` hands each object's seed views to a pool of ``workers``
processes (one torch thread each) and yields the results in input order, with at most
``2 · workers`` jobs of a few objects each in flight (memory: that many objects' views,
never all of them); the objects of a job share their flows' calls (batched over objects).
Views come back through shared memory (torch's multiprocessing reductions), not pickles.

The worker processes are *spawned* (a fresh interpreter each, never ``fork``: forking a
process whose OpenMP pool already started can hang the child). A script that calls this
at import time must therefore keep its entry point under ``if __name__ == "__main__":``,
as for any ``multiprocessing`` code. ``workers=0`` runs everything in this process.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import math
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from contextlib import ExitStack
from typing import Any, TypeVar

import torch
import torch.multiprocessing as mp

import torch_eigview._tuning as _tuning
from torch_eigview.check import as_angle_tensor, check_choice, check_int
from torch_eigview.scale.job_warnings import routing
from torch_eigview.scale.thread_policy import allowed_cpus
from torch_eigview.synthesis import (
    PairGeometry,
    SynthesisOptions,
    SynthesizedViews,
    check_seeds,
    iter_object_geometries,
    synthesize_views,
)

__all__ = [
    "KINDS",
    "available_cpus",
    "each_or_alone",
    "group_size",
    "grouped",
    "map_ordered",
    "object_workers",
    "own_views",
    "synthesize_objects",
]

R = TypeVar("R")
T = TypeVar("T")

#: What :func:`map_ordered` runs its jobs in.
KINDS = ("process", "thread")


def available_cpus() -> int:
    """The number of CPUs this process may run on (its affinity mask where the OS has one)."""
    return len(allowed_cpus())


def object_workers(n_views: int, pixels: int, n_objects: int, kind: str = "process") -> int:
    """The commands' workers for synthesizing ``n_views`` views of ``pixels`` pixels each
    over ``n_objects`` objects: one per CPU this process may use, at most one per object.

    Threads (``kind="thread"``) cost nothing to start, so there is one per CPU whenever
    there are two objects and two CPUs, and torch runs one intra-op thread (the commands'
    policy; with more, as under ``--threads 2``, each worker thread's OpenMP team would
    oversubscribe the cores, so there are none). A process pays a fresh interpreter's
    start (importing torch, kornia and scikit-image), so processes start only for at least
    ``torch_eigview._tuning.PARALLEL_PIXELS`` synthesized pixels, where the work repays
    it, else 0 (synthesis in the calling process).

    Each worker runs one torch thread, and the workers do not wait for each other while
    they run, so a busy neighbour slows them as it slows any process instead of making
    threads spin.
    """
    kind = check_choice(kind, "kind", KINDS)
    cpus = available_cpus()
    if cpus < 2 or n_objects < 2:
        return 0
    if kind == "process" and n_views * pixels < _tuning.PARALLEL_PIXELS:
        return 0
    if kind == "thread" and torch.get_num_threads() > 1:
        return 0
    return min(cpus, n_objects)


def _init_worker() -> None:
    # One thread per process: the parallelism is over objects, and torch's OpenMP pool
    # in every worker would oversubscribe the cores.
    torch.set_num_threads(1)


def synthesize_objects(
    objects: Iterable[torch.Tensor],
    alpha: float | Sequence[float],
    thetas: object,
    options: SynthesisOptions | None = None,
    *,
    workers: int = 0,
    kind: str = "process",
    group: int = 4,
) -> Iterator[SynthesizedViews]:
    """:func:`~torch_eigview.synthesis.synthesize_views` for each object, over ``workers`` processes or threads.

    Args:
        objects: iterable of (V, C, H, W) seed views, one entry per object (consumed
            lazily: at most ``2 · workers`` groups of objects are read ahead).
        alpha: angle between consecutive seed views in degrees, or one angle per seed pair;
            the same for every object.
        thetas: (T,) novel angles in degrees from the first seed view.
        options: :class:`~torch_eigview.synthesis.SynthesisOptions`.
        workers: worker processes or threads; 0 synthesizes in this process (no pool, no
            start-up cost). :func:`available_cpus` is the natural choice for a large build.
        kind: ``"process"`` (spawned, one torch thread each) or ``"thread"`` (threads of
            this process: no start-up cost; run them under ``threads(1)``), see
            :func:`map_ordered`.
        group: objects per job (>= 1), their seed pairs' flows batched (the same views;
            a worker thread calls torch a few times per batch instead of per object).

    Yields:
        One :class:`~torch_eigview.synthesis.SynthesizedViews` per object, in the order
        of ``objects``, identical to :func:`~torch_eigview.synthesis.synthesize_views`'s
        (with ``workers > 0`` on the CPU, whatever the seeds' device: the workers run
        on the CPU).

    Raises:
        TypeError / ValueError: a bad ``workers``, ``thetas`` or ``options``, or a first
            object or ``alpha`` that ``synthesize_views`` refuses (before any process
            starts); any later object's error when that object's turn comes (the pool
            is shut down).

    Example:
        >>> textures = torch.rand(3, 1, 1, 8, 8, generator=torch.Generator().manual_seed(0))
        >>> blocky = textures.repeat_interleave(4, -1).repeat_interleave(4, -2)  # 3 objects, 32 x 32
        >>> seeds = [torch.cat([t, t.roll(1, -1)]) for t in blocky]  # two views a column apart each
        >>> [s.views.shape[0] for s in synthesize_objects(seeds, 5.0, [0.0, 2.5, 5.0])]
        [3, 3, 3]
    """
    workers = check_int(workers, "workers", minimum=0)  # 0: synthesize in this process
    kind = check_choice(kind, "kind", KINDS)
    group = check_int(group, "group", minimum=1)
    if options is not None and not isinstance(options, SynthesisOptions):
        raise TypeError(f"options must be a SynthesisOptions or None, got {type(options).__name__}")
    angles = as_angle_tensor(thetas, "thetas").tolist()  # checked here, not in a worker
    it = iter(objects)
    first = next(it, None)
    if first is None:
        return
    if workers:  # the first object is checked here, before any process starts (its alpha too)
        check_seeds(_as_seeds(first), alpha)
    # A copy: sending a tensor moves its whole storage into shared memory, and the caller's
    # tensor (or the larger tensor it is a view of) with it.
    copy = workers and kind == "process"
    sent = (
        _as_seeds(seeds) if not copy else _as_seeds(seeds).detach().to("cpu", copy=True)
        for seeds in itertools.chain([first], it)
    )
    jobs = ((objs, alpha, angles, options) for objs in grouped(sent, group))
    results = map_ordered(_synthesize_group, jobs, workers, finish=_own_group, kind=kind)
    with contextlib.closing(results):  # closing this generator ends the pool
        for outcomes in results:
            for out in outcomes:
                if isinstance(out, Exception):
                    raise out
                yield out


def _synthesize_group(
    objects: list[torch.Tensor],
    alpha: float | Sequence[float],
    angles: list[float],
    options: SynthesisOptions | None,
) -> list[SynthesizedViews | Exception]:
    """:func:`~torch_eigview.synthesis.synthesize_views` of each object, the seed pairs'
    flows of all of them batched (:func:`~torch_eigview.synthesis.iter_object_geometries`:
    the same views), or the error that refused an object, in its place (the objects
    before it are the caller's to yield first)."""
    try:
        records = iter_object_geometries(objects, alpha, options)
    except Exception:  # an object the flows refuse: each alone, its error its own
        records = None

    def one(seeds: torch.Tensor, shared: Iterator[list[PairGeometry]] | None) -> SynthesizedViews | Exception:
        try:
            geometry = None if shared is None else next(shared)
            return synthesize_views(seeds, alpha, angles, options, geometry=geometry)
        except Exception as exc:  # raised in the caller's thread at this object's turn
            return exc

    return each_or_alone(objects, records, one)


def each_or_alone(jobs: Sequence[T], shared: Any, one: Callable[[T, Any], R]) -> list[R]:
    """``one(job, shared)`` for each of a group's jobs, ``shared`` what they share (a group's
    batched flows), or None; from the first job whose outcome is an exception on, each
    job alone (``one(job, None)``), so that an error is its own job's and not the
    batch's. The outcomes in the jobs' order."""
    out: list[R] = []
    for i, job in enumerate(jobs):
        outcome = one(job, shared)
        if isinstance(outcome, Exception) and shared is not None:
            return out + [one(j, None) for j in jobs[i:]]
        out.append(outcome)
    return out


def _own_group(outcomes: list[SynthesizedViews | Exception]) -> list[SynthesizedViews | Exception]:
    """A worker process's group with its views copied out of shared memory."""
    return [out if isinstance(out, Exception) else own_views(out) for out in outcomes]


def group_size(n_objects: int, workers: int, object_bytes: int = 0) -> int:
    """Objects per job for ``n_objects`` over ``workers`` (0: this process): as few jobs as
    ``torch_eigview._tuning.GROUP_OBJECTS`` objects a job allow (their flows batched, a
    job's views held until it returns), in a multiple of the workers so that they finish
    together (20 objects over 2 workers: 4 jobs of 5), and no more objects than keep a job's
    views, ``object_bytes`` each, within ``torch_eigview._tuning.GROUP_BYTES`` (at least
    one). The objects' views do not depend on it."""
    slots = max(1, workers)
    per_job = _tuning.GROUP_OBJECTS
    if object_bytes > 0:
        per_job = max(1, min(per_job, _tuning.GROUP_BYTES // object_bytes))
    jobs = slots * max(1, math.ceil(n_objects / (slots * per_job)))
    return max(1, math.ceil(n_objects / jobs))


def grouped(items: Iterable[T], size: int) -> Iterator[list[T]]:
    """``items`` in lists of ``size`` (the last one shorter), read lazily; an error raised
    while reading an item comes after the list of the items read before it."""
    it = iter(items)
    while True:
        group: list[T] = []
        try:
            for _ in range(size):
                group.append(next(it))
        except StopIteration:
            if group:
                yield group
            return
        except Exception:
            if group:
                yield group
            raise
        yield group


def own_views(out: SynthesizedViews) -> SynthesizedViews:
    """``out`` with its views copied out of the shared memory a worker sent them in."""
    # Out of the shared-memory segment it came in (a /dev/shm file per object otherwise,
    # for as long as the caller keeps the views).
    return dataclasses.replace(out, views=out.views.clone())


def map_ordered(
    fn: Callable[..., R],
    jobs: Iterable[tuple[Any, ...]],
    workers: int,
    *,
    finish: Callable[[R], R] | None = None,
    kind: str = "process",
    always: tuple[type[Warning], ...] = (),
) -> Generator[R, None, None]:
    """``fn(*job)`` for each job, in the order of ``jobs``, over ``workers`` processes or threads.

    At most ``2 · workers`` jobs are in flight (``jobs`` is consumed lazily, in this
    thread), and an error of ``fn`` is raised when its job's turn comes, after which the
    pool shuts down. An error raised by ``jobs`` itself comes after the results (or the
    error) of the jobs read before it, as in order.
    ``workers=0`` calls ``fn`` in this process.

    - ``kind="process"``: spawned processes, each with one torch thread; tensors travel
      through shared memory. For work that holds Python's GIL (numpy-heavy code).
    - ``kind="thread"``: threads of this process, for work that runs in torch kernels
      (they release the GIL): no start-up cost, nothing copied. Each thread's torch
      operations use torch's intra-op threads as the caller set them: run the pool under
      :func:`~torch_eigview.scale.thread_policy.threads` ``(1)``, as the commands do (the
      parallelism is over jobs; an OpenMP team per thread would oversubscribe the
      cores). Warnings raised inside a job's
      :func:`~torch_eigview.scale.job_warnings.job_warnings` go to that job only.

    Args:
        fn: a module-level function for processes (the workers import it by name).
        jobs: argument tuples.
        workers: worker processes or threads, 0 for none.
        finish: applied to each result of a worker process in this process (e.g. to copy
            its tensors out of shared memory); not to results computed in this process.
        kind: ``"process"`` or ``"thread"``.
        always: with threads, warning categories shown every time while the pool is open
            (:func:`~torch_eigview.scale.job_warnings.routing`), so that each job's
            :func:`~torch_eigview.scale.job_warnings.job_warnings` gets its own.

    Yields:
        The results, in order. Close the generator (``contextlib.closing``) if you stop
        early or may raise while consuming: that ends the pool and its warning routing.
    """
    workers = check_int(workers, "workers", minimum=0)
    kind = check_choice(kind, "kind", KINDS)
    if workers == 0:
        for job in jobs:
            yield fn(*job)
        return
    with ExitStack() as stack:
        if kind == "thread":
            stack.enter_context(routing(*always))
            pool: Executor = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="eigview-job")
        else:
            pool = ProcessPoolExecutor(
                max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_init_worker
            )
        pending: deque[Future[R]] = deque()

        def collect() -> R:
            out = pending.popleft().result()
            return out if finish is None or kind == "thread" else finish(out)

        try:
            source = iter(jobs)
            while True:
                try:
                    job = next(source)
                except StopIteration:
                    break
                except Exception:
                    # Reading a job failed: the jobs before it come first, as they would
                    # in order (their results, or the first one's error).
                    while pending:
                        yield collect()
                    raise
                pending.append(pool.submit(fn, *job))
                if len(pending) >= 2 * workers:
                    yield collect()
            while pending:
                yield collect()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _as_seeds(seeds: object) -> torch.Tensor:
    if not isinstance(seeds, torch.Tensor):
        raise TypeError(f"objects must yield (V, C, H, W) tensors, got {type(seeds).__name__}")
    return seeds
