"""Synthesis of many objects over worker processes, in order, with bounded memory.

Per object the build is optical flow (scikit-image, one core) and the warp maps (many
small torch operations that two OpenMP threads barely speed up). Objects are independent,
so the cheap way to use the machine's cores is one object per process:
:func:`synthesize_objects` hands each object's seed views to a pool of ``workers``
processes (one torch thread each) and yields the results in input order, with at most
``2 · workers`` objects in flight (memory: that many objects' views, never all of them).
Views come back through shared memory (torch's multiprocessing reductions), not pickles.

The worker processes are *spawned* (a fresh interpreter each, never ``fork``: forking a
process whose OpenMP pool already started can hang the child). A script that calls this
at import time must therefore keep its entry point under ``if __name__ == "__main__":``,
as for any ``multiprocessing`` code. ``workers=0`` runs everything in this process.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor

import torch
import torch.multiprocessing as mp

from torch_eigview.check import as_angle_tensor, check_int
from torch_eigview.scale.thread_policy import allowed_cpus
from torch_eigview.synthesis import SynthesisOptions, SynthesizedViews, check_seeds, synthesize_views

__all__ = ["available_cpus", "synthesize_objects"]


def available_cpus() -> int:
    """The number of CPUs this process may run on (its affinity mask where the OS has one)."""
    return len(allowed_cpus())


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
) -> Iterator[SynthesizedViews]:
    """:func:`~torch_eigview.synthesis.synthesize_views` for each object, over ``workers`` processes.

    Args:
        objects: iterable of (V, C, H, W) seed views, one entry per object (consumed
            lazily: at most ``2 · workers`` objects are read ahead).
        alpha: angle between consecutive seed views in degrees, or one angle per seed pair;
            the same for every object.
        thetas: (T,) novel angles in degrees from the first seed view.
        options: :class:`~torch_eigview.synthesis.SynthesisOptions`.
        workers: worker processes; 0 synthesizes in this process (no pool, no start-up
            cost). :func:`available_cpus` is the natural choice for a large build.

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
        >>> from torch_eigview.apps.bench_scaling import smooth_views
        >>> seeds = [smooth_views(o, 6, 1, 32)[[0, 5]] for o in range(3)]
        >>> [s.views.shape[0] for s in synthesize_objects(seeds, 5.0, [0.0, 2.5, 5.0])]
        [3, 3, 3]
    """
    workers = check_int(workers, "workers", minimum=0)  # 0: synthesize in this process
    if options is not None and not isinstance(options, SynthesisOptions):
        raise TypeError(f"options must be a SynthesisOptions or None, got {type(options).__name__}")
    angles = as_angle_tensor(thetas, "thetas").tolist()  # checked here, not in a worker
    it = iter(objects)
    if workers == 0:
        for seeds in it:
            yield synthesize_views(_as_seeds(seeds), alpha, angles, options)
        return
    first = next(it, None)
    if first is None:
        return
    # The first object is checked here, before any process starts (its alpha too).
    check_seeds(_as_seeds(first), alpha)
    context = mp.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_init_worker)
    pending: deque[Future[SynthesizedViews]] = deque()

    def collect() -> SynthesizedViews:
        out = pending.popleft().result()
        # Out of the shared-memory segment it came in (a /dev/shm file per object otherwise,
        # for as long as the caller keeps the views).
        return dataclasses.replace(out, views=out.views.clone())

    try:
        for seeds in itertools.chain([first], it):
            # A copy: sending a tensor moves its whole storage into shared memory, and the
            # caller's tensor (or the larger tensor it is a view of) with it.
            pending.append(
                pool.submit(
                    synthesize_views, _as_seeds(seeds).detach().to("cpu", copy=True), alpha, angles, options
                )
            )
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
