"""The warnings of one job, whether it runs in this thread, in a pool thread or in a worker process.

A job of :func:`~torch_eigview.scale.parallel.map_ordered` returns the warnings it raised
so that the caller can re-issue them with the job named (a worker process's would
otherwise be lost). ``warnings.catch_warnings`` records them in a process that runs one
job at a time, but it swaps process-wide state (the filters and ``showwarning``), so two
threads inside it at once would record each other's warnings and restore each other's
state. A thread pool therefore runs under :func:`routing`: one handler for the whole
process, installed by the first pool open and removed by the last one to close, hands
every warning shown in a thread inside :func:`job_warnings` to that job's list, and
everything else to the handler that was there before. The caller's filters stay in force;
only the categories a pool names are shown every time (not once per place) while it is
open, so that each job's warning reaches its own list.

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
# The open routing() contexts and the handler that was installed before the first one.
_STATE: dict[str, Any] = {"depth": 0, "previous": None}


def _route(
    message: Any, category: Any, filename: Any, lineno: Any, file: Any = None, line: Any = None
) -> None:
    sink = getattr(_LOCAL, "sink", None)
    if sink is None:
        _STATE["previous"](message, category, filename, lineno, file, line)
    else:
        sink.append(warnings.WarningMessage(message, category, filename, lineno, file, line))


def _filter_list() -> list[tuple[Any, ...]]:
    return warnings.filters  # type: ignore[return-value]  # a list, typed as a Sequence


def _filters_changed() -> None:
    # What warnings.filterwarnings does after changing the list: the modules' registries
    # of warnings already shown are keyed by a version of the filters.
    mutated = getattr(warnings, "_filters_mutated", None)
    if callable(mutated):
        mutated()


def _remove_filters(entries: list[tuple[Any, ...]]) -> None:
    filters = _filter_list()
    for entry in entries:
        for i, existing in enumerate(filters):
            if existing is entry:  # ours, not an equal one of the caller's
                del filters[i]
                break
    if entries:
        _filters_changed()


@contextmanager
def routing(*always: type[Warning]) -> Iterator[None]:
    """While open, a warning shown in a thread inside :func:`job_warnings` goes to that job's
    list; the others go to the handler that was there before. Enter it in the thread that
    starts the pool; pools may open and close in any order.

    Args:
        *always: categories shown every time while the pool is open (each job needs its
            own copy, not the first job's alone); the caller's filters decide the rest.
    """
    with _LOCK:
        if _STATE["depth"] == 0:
            _STATE["previous"] = warnings.showwarning
            warnings.showwarning = _route
        _STATE["depth"] += 1
        added: list[tuple[Any, ...]] = [("always", None, category, None, 0) for category in always]
        filters = _filter_list()
        for entry in added:
            filters.insert(0, entry)
        if added:
            _filters_changed()
    try:
        yield
    finally:
        with _LOCK:
            _remove_filters(added)
            _STATE["depth"] -= 1
            if _STATE["depth"] == 0:
                if warnings.showwarning is _route:  # not replaced by someone else meanwhile
                    warnings.showwarning = _STATE["previous"]
                _STATE["previous"] = None


@contextmanager
def job_warnings(*always: type[Warning]) -> Iterator[list[warnings.WarningMessage]]:
    """The warnings raised in the body, as a list filled when the body ends.

    Args:
        *always: categories recorded every time they are raised, not once per place
            (under :func:`routing`, the categories its pool names are).

    Yields:
        A list of ``warnings.WarningMessage``.
    """
    if _STATE["depth"]:  # a pool's thread: the handler routes by thread
        sink: list[warnings.WarningMessage] = []
        previous = getattr(_LOCAL, "sink", None)
        _LOCAL.sink = sink
        try:
            yield sink
        finally:
            _LOCAL.sink = previous
        return
    with warnings.catch_warnings(record=True) as caught:
        for category in always:
            warnings.simplefilter("always", category)
        yield caught
