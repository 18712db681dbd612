"""The warnings of one job, whether it runs in this thread, in a pool thread or in a worker process.

A job of :func:`~torch_eigview.scale.parallel.map_ordered` returns the warnings it raised
so that the caller can re-issue them with the job named (a worker process's would
otherwise be lost). ``warnings.catch_warnings`` records them in a process that runs one
job at a time, but it swaps process-wide state (the filters and ``showwarning``), so two
threads inside it at once would record each other's warnings and restore each other's
state. A thread pool therefore runs under :func:`routing`: one handler, installed once
by the calling thread, hands every warning to the list of the job whose thread raised it
(:func:`job_warnings`).

Example:
    >>> import warnings
    >>> with job_warnings() as caught:
    ...     warnings.warn("seed pair 0: flat")
    >>> [str(w.message) for w in caught]
    ['seed pair 0: flat']
"""

from __future__ import annotations

import threading
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["job_warnings", "routing"]

_LOCAL = threading.local()
_LOCK = threading.Lock()
_ROUTES = [0]  # routing() contexts open in this process


@contextmanager
def routing() -> Iterator[None]:
    """While open, every warning raised in a thread inside :func:`job_warnings` goes to that
    job's list, shown every time (each job's caller decides what to show); the others go
    to the handler that was there before. Enter it in the thread that starts the pool."""
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        shown = warnings.showwarning

        def show(
            message: Any, category: Any, filename: Any, lineno: Any, file: Any = None, line: Any = None
        ) -> None:
            sink = getattr(_LOCAL, "sink", None)
            if sink is None:
                shown(message, category, filename, lineno, file, line)
            else:
                sink.append(warnings.WarningMessage(message, category, filename, lineno, file, line))

        warnings.showwarning = show
        with _LOCK:
            _ROUTES[0] += 1
        try:
            yield
        finally:
            with _LOCK:
                _ROUTES[0] -= 1


@contextmanager
def job_warnings(*always: type[Warning]) -> Iterator[list[warnings.WarningMessage]]:
    """The warnings raised in the body, as a list filled when the body ends.

    Args:
        *always: categories recorded every time they are raised, not once per place
            (under :func:`routing` every category is).

    Yields:
        A list of ``warnings.WarningMessage``.
    """
    if _ROUTES[0]:  # a pool's thread (the handler routes by thread)
        sink: list[warnings.WarningMessage] = []
        _LOCAL.sink = sink
        try:
            yield sink
        finally:
            _LOCAL.sink = None
        return
    with warnings.catch_warnings(record=True) as caught:
        for category in always:
            warnings.simplefilter("always", category)
        yield caught
