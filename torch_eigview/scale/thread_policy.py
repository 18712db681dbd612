"""How many threads a command's torch (and BLAS) operations use: a policy and a context manager.

The map building, the warp and the flow are many small operations on tensors of a few
MB: a second OpenMP thread halves each operation's little work but adds a barrier to it,
and beside a process that keeps the cores busy the threads of a parallel region wait at
every barrier for a descheduled partner, spinning. One intra-op thread per process never
waits for another, so it is the default of the ``eigview`` commands
(:func:`default_threads`; the cost model is ``torch_eigview._tuning``'s); the parallelism
that does pay is over objects, one worker each
(:func:`~torch_eigview.scale.parallel.synthesize_objects` with ``workers``, whose workers
run one thread each).

Library functions never change the thread settings: the commands apply the policy with
the :func:`threads` context manager, which restores the caller's settings on exit, and a
script may do the same::

    with threads(1):
        views = synthesize_views(seeds, 5.0, thetas)

Large matrix products are the exception: a Gram matrix of thousands of views is one
long compute-bound operation that splits evenly over idle cores, and stalls like the rest
beside a busy neighbour. The commands run their eigen step with :func:`product_threads`,
which counts the CPUs that other processes leave idle (sampled for a tenth of a second
just before the step) and uses that many threads, at least one.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from contextvars import ContextVar
from pathlib import Path

import torch

import torch_eigview._tuning as _tuning
from torch_eigview.check import check_int, check_limit, check_positive

__all__ = [
    "allowed_cpus",
    "default_threads",
    "eigen_flops",
    "for_products",
    "idle_cpus",
    "product_threads",
    "resolve_threads",
    "threads",
]

#: Seconds :func:`idle_cpus` may sample for.
_MAX_INTERVAL = 60.0
# True inside threads(None), the commands' policy; an explicit count turns it off.
_POLICY: ContextVar[bool] = ContextVar("torch_eigview_thread_policy", default=False)


def default_threads() -> int:
    """The commands' default number of intra-op threads: ``torch_eigview._tuning``'s
    ``THREADS_DEFAULT`` (one), never more than torch would use itself
    (``torch.get_num_threads()``, e.g. under ``OMP_NUM_THREADS``)."""
    return max(1, min(_tuning.THREADS_DEFAULT, torch.get_num_threads()))


def resolve_threads(n: int | None) -> int:
    """``n`` checked (an int >= 1), or :func:`default_threads` for None."""
    if n is None:
        return default_threads()
    count = check_int(n, "threads", minimum=1)
    check_limit(count, "threads", "threads", "max_threads")  # each one a stack and a pool slot
    return count


def allowed_cpus() -> list[int]:
    """The ids of the CPUs this process may run on (its affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return list(range(os.cpu_count() or 1))  # pragma: no cover - macOS / Windows


def _idle_ticks(stat: Path, cpus: list[int]) -> tuple[int, int] | None:
    """(idle, total) clock ticks summed over ``cpus`` from a ``/proc/stat`` file, or None."""
    try:
        lines = stat.read_text().splitlines()
    except OSError:
        return None
    wanted = {f"cpu{i}" for i in cpus}
    idle = total = 0
    for line in lines:
        fields = line.split()
        if fields and fields[0] in wanted:
            ticks = [int(v) for v in fields[1:9]]  # user nice system idle iowait irq softirq steal
            idle += ticks[3] + ticks[4]
            total += sum(ticks)
    return (idle, total) if total else None


def idle_cpus(interval: float = 0.1, *, stat: str | os.PathLike[str] = "/proc/stat") -> float:
    """CPUs of this process's affinity mask that stayed idle over the next ``interval`` seconds.

    The calling thread sleeps while it samples, so the figure is what the other processes
    (and this process's other threads) leave free. Where the kernel has no ``/proc/stat``
    (macOS, Windows), every allowed CPU counts as idle.

    Args:
        interval: sampling time in seconds, > 0.
        stat: the kernel's CPU statistics file (a parameter for tests).

    Returns:
        A float in [0, number of allowed CPUs].
    """
    check_positive(interval, "interval")
    if interval > _MAX_INTERVAL:
        raise ValueError(
            f"interval={interval!r} must be at most {_MAX_INTERVAL:g} seconds (a sample, not a wait)"
        )
    if os.path.exists(stat) and not os.path.isfile(stat):  # a FIFO would block the read forever
        raise ValueError(f"stat={os.fspath(stat)!r} must be a regular file (the kernel's /proc/stat)")
    cpus = allowed_cpus()
    first = _idle_ticks(Path(stat), cpus)
    if first is None:
        return float(len(cpus))
    time.sleep(interval)
    second = _idle_ticks(Path(stat), cpus)
    if second is None or second[1] <= first[1]:
        return float(len(cpus))
    return len(cpus) * (second[0] - first[0]) / (second[1] - first[1])


def eigen_flops(n_views: int, n_features: int) -> int:
    """Multiply-adds of an exact eigenspace fit of ``n_views`` views of ``n_features`` values:
    the Gram matrix (P < N) or the scatter matrix (N <= P), min² · max."""
    return min(n_views, n_features) ** 2 * max(n_views, n_features)


def product_threads(interval: float = 0.1) -> int:
    """Threads for a large matrix product: the CPUs other processes leave idle.

    Args:
        interval: sampling time of :func:`idle_cpus` in seconds.

    Returns:
        The idle CPUs rounded down after adding 0.3 (a CPU 70 % idle counts), at least 1
        and at most the CPUs this process may use.
    """
    idle = idle_cpus(interval)
    return max(1, min(len(allowed_cpus()), int(idle + 0.3)))


@contextmanager
def for_products(flops: float) -> Iterator[int]:
    """Runs a matrix-product step of about ``flops`` operations under the commands' policy.

    Inside :func:`threads` with no count (the commands' default policy) and for a product
    of at least ``torch_eigview._tuning.PRODUCT_FLOPS`` operations, the body runs with
    :func:`product_threads`; with an explicit count (``--threads N``), outside any policy
    (library use), or for a smaller product (where sampling the CPUs would cost a large
    share of what it gains), the thread settings stay as they are.

    Yields:
        The number of threads in force.

    Example:
        >>> with threads(1), for_products(1e6) as n:  # small: one thread, no sampling
        ...     n
        1
    """
    check_positive(flops, "flops", allow_zero=True)
    if not _POLICY.get() or flops < _tuning.PRODUCT_FLOPS:
        yield torch.get_num_threads()
        return
    with threads(product_threads()) as n:
        yield n


@contextmanager
def threads(n: int | None = None, *, blas: bool = True) -> Iterator[int]:
    """Runs the body with ``n`` intra-op threads, then restores the previous settings.

    Args:
        n: torch intra-op threads (``torch.set_num_threads``), >= 1; None applies the
            commands' policy, :func:`default_threads`.
        blas: also limit the BLAS and OpenMP pools that numpy and scikit-image use
            (``threadpoolctl``, when installed) to ``n``.

    Yields:
        The number of threads in force.

    Raises:
        TypeError / ValueError: ``n`` is not an int >= 1.

    Example:
        >>> before = torch.get_num_threads()
        >>> with threads(1) as n:
        ...     n, torch.get_num_threads()
        (1, 1)
        >>> torch.get_num_threads() == before
        True
    """
    count = resolve_threads(n)
    previous = torch.get_num_threads()
    with ExitStack() as stack:
        if blas:
            try:
                from threadpoolctl import threadpool_limits
            except ImportError:  # an optional dependency: torch's own pool is still set
                pass
            else:
                stack.enter_context(threadpool_limits(limits=count))
        torch.set_num_threads(count)
        token = _POLICY.set(n is None)
        try:
            yield count
        finally:
            _POLICY.reset(token)
            torch.set_num_threads(previous)
