"""One object's synthesized gallery as a job for a worker thread or process (or this one).

:class:`~torch_eigview.evaluation.coil.CoilExperiment` hands each object's seeds to
:func:`synthesize_object` through :func:`object_galleries`, a few objects to a pool job
(:func:`synthesize_group`: their flows batched). A
worker's warnings would be lost and its errors would name no object, so the job returns
both for the experiment to re-issue with the object named.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterable, Iterator
from typing import Any

import torch

from torch_eigview.scale.job_warnings import job_warnings
from torch_eigview.scale.parallel import each_or_alone, grouped, map_ordered, own_views
from torch_eigview.synthesis import (
    ElevationFallbackWarning,
    PairGeometry,
    SynthesisOptions,
    SynthesizedViews,
    iter_object_geometries,
    synthesize_circle,
    synthesize_views,
)

__all__ = ["CaughtWarning", "object_galleries", "own_outcome", "synthesize_group", "synthesize_object"]


#: A warning caught in :func:`synthesize_object`: message, category, file and line.
CaughtWarning = tuple[str, type[Warning], str, int]


def synthesize_object(
    seeds: torch.Tensor,
    alpha: float,
    thetas: list[float] | None,
    step: float,
    options: SynthesisOptions,
    overlap: float,
    records: Iterator[list[PairGeometry]] | None = None,
) -> tuple[SynthesizedViews, list[CaughtWarning]] | ValueError:
    """One object's ``nvs`` gallery, in this process, a pool thread or a worker process: the views at ``thetas``
    from seeds α apart, or with ``thetas`` None the full circle every ``step`` degrees
    (:func:`~torch_eigview.evaluation.circle.synthesize_circle`).

    Args:
        records: the seed pairs' geometry of a group's objects (:func:`_group_records`),
            this object's next; None measures it here.

    Returns:
        The views and the warnings raised on the way (a worker's would be lost: the caller
        re-issues them), or the ``ValueError`` that refused the object's seeds, for the
        caller to name the object.
    """
    with job_warnings(ElevationFallbackWarning) as caught:
        try:
            geometry = None if records is None else next(records)
            if thetas is None:
                out = synthesize_circle(seeds, step, options, overlap=overlap, geometry=geometry)
            else:
                out = synthesize_views(seeds, alpha, thetas, options, geometry=geometry)
        except ValueError as exc:
            return exc
    return out, [(str(w.message), w.category, w.filename, w.lineno) for w in caught]


def synthesize_group(
    jobs: list[tuple[Any, ...]],
) -> list[tuple[SynthesizedViews, list[CaughtWarning]] | ValueError]:
    """:func:`synthesize_object` of each job (one experiment's: the same angles and options),
    the seed pairs' flows of all of them batched
    (:func:`~torch_eigview.synthesis.iter_object_geometries`, the same views): one call
    per flow for a few objects costs a worker thread far less of Python's GIL than one per
    object. From an object whose seeds are refused on, each object is synthesized alone,
    so that the error is its own."""
    _, alpha, thetas, step, options, overlap = jobs[0]
    try:
        records = _group_records([job[0] for job in jobs], alpha, thetas, options)
    except ValueError:
        records = None
    return each_or_alone(
        jobs,
        records,
        lambda job, shared: synthesize_object(job[0], alpha, thetas, step, options, overlap, shared),
    )


def _group_records(
    seeds: list[torch.Tensor], alpha: float, thetas: list[float] | None, options: SynthesisOptions
) -> Iterator[list[PairGeometry]]:
    """Each object's seed-pair records, the flows batched over the objects: its pairs
    α apart, or with ``thetas`` None the full circle's M pairs (seeds k and k + 1 mod M)."""
    if thetas is not None:
        return iter_object_geometries(seeds, alpha, options)
    m = seeds[0].shape[0]
    pairs = iter_object_geometries([s[[k, (k + 1) % m]] for s in seeds for k in range(m)], 360.0 / m, options)
    return ([next(pairs)[0] for _ in range(m)] for _ in seeds)


def own_outcome(
    outcome: tuple[SynthesizedViews, list[CaughtWarning]] | ValueError,
) -> tuple[SynthesizedViews, list[CaughtWarning]] | ValueError:
    """A worker's outcome with its views copied out of the shared memory they came in."""
    if isinstance(outcome, ValueError):
        return outcome
    out, caught = outcome
    return own_views(out), caught


def _own_outcomes(
    outcomes: list[tuple[SynthesizedViews, list[CaughtWarning]] | ValueError],
) -> list[tuple[SynthesizedViews, list[CaughtWarning]] | ValueError]:
    return [own_outcome(o) for o in outcomes]


def object_galleries(
    jobs: Iterable[tuple[Any, ...]], objects: Iterable[int], workers: int, kind: str, group: int = 1
) -> Iterator[tuple[int, SynthesizedViews]]:
    """``(obj, views)`` per object, in order: :func:`synthesize_object` of each job over
    ``workers`` threads or processes (:func:`~torch_eigview.scale.parallel.map_ordered`),
    ``group`` objects to a pool job (:func:`synthesize_group`).

    A refusal is raised as an error naming its object (the pool then closes); each
    object's warnings are re-issued with the object named once the pool has closed, under
    the caller's own warning filters.
    """
    results = map_ordered(
        synthesize_group,
        ((g,) for g in grouped(jobs, group)),
        workers,
        finish=_own_outcomes,
        kind=kind,
        always=(ElevationFallbackWarning,),
    )
    caught_all: list[CaughtWarning] = []
    with contextlib.closing(results):  # an error here ends the pool (and its warning routing)
        outcomes = (outcome for group_outcomes in results for outcome in group_outcomes)
        for obj, outcome in zip(objects, outcomes, strict=True):
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
