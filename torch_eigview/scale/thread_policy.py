"""How many threads a command's torch (and BLAS) operations use: a policy and a context manager.

The map building, the warp and the flow are many small operations on tensors of a few
MB: a second OpenMP thread barely helps them on a quiet machine (two threads took 0.84×
the one-thread time of a COIL-20 run), and beside a process that keeps the cores busy
the threads of a parallel region wait for each other and spin, and the same run took
5–8× longer. One intra-op thread per process never collapses that way, so it is the
default of the ``eigview`` commands (:func:`default_threads`); the parallelism that does
pay is over objects, one process each (:func:`~torch_eigview.scale.parallel.synthesize_objects`
with ``workers``, whose workers run one thread each).

Library functions never change the thread settings: the commands apply the policy with
the :func:`threads` context manager, which restores the caller's settings on exit, and a
script may do the same::

    with threads(1):
        views = synthesize_views(seeds, 5.0, thetas)
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

import torch

from torch_eigview.check import check_int

__all__ = ["THREADS_DEFAULT", "default_threads", "resolve_threads", "threads"]

#: Intra-op threads of a command unless ``--threads`` says otherwise (see the module).
THREADS_DEFAULT = 1


def default_threads() -> int:
    """The commands' default number of intra-op threads: :data:`THREADS_DEFAULT`, never more
    than torch would use itself (``torch.get_num_threads()``, e.g. under ``OMP_NUM_THREADS``)."""
    return max(1, min(THREADS_DEFAULT, torch.get_num_threads()))


def resolve_threads(n: int | None) -> int:
    """``n`` checked (an int >= 1), or :func:`default_threads` for None."""
    if n is None:
        return default_threads()
    return check_int(n, "threads", minimum=1)


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
        try:
            yield count
        finally:
            torch.set_num_threads(previous)
