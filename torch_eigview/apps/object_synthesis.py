"""One object's synthesized gallery as a job for a worker thread or process (or this one).

:class:`~torch_eigview.apps.experiment.CoilExperiment` hands each object's seeds to
:func:`synthesize_object` through :func:`object_galleries`. A
worker's warnings would be lost and its errors would name no object, so the job returns
both for the experiment to re-issue with the object named.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterable, Iterator
from typing import Any

import torch

from torch_eigview.apps.circle import synthesize_circle
from torch_eigview.scale.job_warnings import job_warnings
from torch_eigview.scale.parallel import map_ordered, own_views
from torch_eigview.synthesis import (
    ElevationFallbackWarning,
    SynthesisOptions,
    SynthesizedViews,
    synthesize_views,
)

__all__ = ["CaughtWarning", "object_galleries", "own_outcome", "synthesize_object"]


#: A warning caught in :func:`synthesize_object`: message, category, file and line.
CaughtWarning = tuple[str, type[Warning], str, int]


def synthesize_object(
    seeds: torch.Tensor,
    alpha: float,
    thetas: list[float] | None,
    step: float,
    options: SynthesisOptions,
    overlap: float,
) -> tuple[SynthesizedViews, list[CaughtWarning]] | ValueError:
    """One object's ``nvs`` gallery, in this process, a pool thread or a worker process: the views at ``thetas``
    from seeds α apart, or with ``thetas`` None the full circle every ``step`` degrees
    (:func:`~torch_eigview.apps.circle.synthesize_circle`).

    Returns:
        The views and the warnings raised on the way (a worker's would be lost: the caller
        re-issues them), or the ``ValueError`` that refused the object's seeds, for the
        caller to name the object.
    """
    with job_warnings(ElevationFallbackWarning) as caught:
        try:
            if thetas is None:
                out = synthesize_circle(seeds, step, options, overlap=overlap)
            else:
                out = synthesize_views(seeds, alpha, thetas, options)
        except ValueError as exc:
            return exc
    return out, [(str(w.message), w.category, w.filename, w.lineno) for w in caught]


def own_outcome(
    outcome: tuple[SynthesizedViews, list[CaughtWarning]] | ValueError,
) -> tuple[SynthesizedViews, list[CaughtWarning]] | ValueError:
    """A worker's outcome with its views copied out of the shared memory they came in."""
    if isinstance(outcome, ValueError):
        return outcome
    out, caught = outcome
    return own_views(out), caught


def object_galleries(
    jobs: Iterable[tuple[Any, ...]], objects: Iterable[int], workers: int, kind: str
) -> Iterator[tuple[int, SynthesizedViews]]:
    """``(obj, views)`` per object, in order: :func:`synthesize_object` of each job over
    ``workers`` threads or processes (:func:`~torch_eigview.scale.parallel.map_ordered`).

    A refusal is raised as an error naming its object (the pool then closes); each
    object's warnings are re-issued with the object named once the pool has closed, under
    the caller's own warning filters.
    """
    results = map_ordered(
        synthesize_object, jobs, workers, finish=own_outcome, kind=kind, always=(ElevationFallbackWarning,)
    )
    caught_all: list[CaughtWarning] = []
    with contextlib.closing(results):  # an error here ends the pool (and its warning routing)
        for obj, outcome in zip(objects, results, strict=True):
            if isinstance(outcome, ValueError):  # e.g. a flow that cannot match this object's seeds
                raise ValueError(f"object {obj}: synthesis failed: {outcome}") from outcome
            out, caught = outcome
            for message, category, filename, lineno in caught:
                if issubclass(category, ElevationFallbackWarning):
                    message = f"object {obj}: {message}"
                caught_all.append((message, category, filename, lineno))
            yield obj, out
    for message, category, filename, lineno in caught_all:
        warnings.warn_explicit(message, category, filename, lineno)
