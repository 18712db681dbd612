"""Objects' synthesized galleries over worker threads or processes, in order.

:class:`~torch_eigview.method.FewViewEigenspace` describes each object's gallery as an
:class:`ObjectJob` (its seed views, their angles, the angles to synthesize and its seed
masks) and :func:`object_galleries` synthesizes them, a few objects to a pool job
(:func:`synthesize_group`) whose seed pairs' flows go in shared calls
(:func:`~torch_eigview.synthesis.iter_object_geometries`: the same views as one object
at a time, and far fewer small calls for a worker thread to run under Python's GIL). A
worker's warnings would be lost and its errors would name no object, so a job returns
both, and :func:`object_galleries` raises the error, or re-issues the warnings, with the
object named.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Hashable, Iterable, Iterator
from dataclasses import dataclass

import torch

from torch_eigview.scale.job_warnings import job_warnings
from torch_eigview.scale.parallel import each_or_alone, grouped, map_ordered, own_views
from torch_eigview.synthesis import (
    Circle,
    ElevationFallbackWarning,
    PairGeometry,
    SynthesisOptions,
    SynthesizedViews,
    iter_object_geometries,
    synthesize_circle,
    synthesize_views,
)

__all__ = ["CaughtWarning", "ObjectJob", "object_galleries", "synthesize_group", "synthesize_object"]


#: A warning caught in :func:`synthesize_object`: message, category, file and line.
CaughtWarning = tuple[str, type[Warning], str, int]

#: A job's outcome: its views and the warnings raised on the way, or the ``ValueError``
#: that refused its seeds.
Outcome = tuple[SynthesizedViews, list[CaughtWarning]] | ValueError


@dataclass(frozen=True)
class ObjectJob:
    """One object's gallery to synthesize.

    Attributes:
        seeds: (V, C, H, W) seed views.
        alpha: the angle between consecutive seeds in degrees, or one per pair (Sec. 4.1's
            α_n); 360/M round the circle.
        thetas: the angles to synthesize, degrees from the first seed; None for the full
            circle (every ``Circle.step`` degrees round it, the seeds evenly spaced).
        masks: (V, H, W) bool seed masks, or None (the brightness threshold).
    """

    seeds: torch.Tensor
    alpha: float | list[float]
    thetas: list[float] | None
    masks: torch.Tensor | None = None

    def owned(self) -> ObjectJob:
        """The job with its own copy of the seeds and masks: a worker process is sent the
        whole storage a view lives in, which for a slice of a larger tensor is more."""
        masks = None if self.masks is None else self.masks.clone()
        return ObjectJob(self.seeds.clone(), self.alpha, self.thetas, masks)


def synthesize_object(
    job: ObjectJob,
    options: SynthesisOptions,
    circle: Circle,
    records: Iterator[list[PairGeometry]] | None = None,
) -> Outcome:
    """One object's views (:func:`~torch_eigview.synthesis.synthesize_views`, or
    :func:`~torch_eigview.synthesis.synthesize_circle` for ``job.thetas`` None) in this
    process, a pool thread or a worker process.

    Args:
        job: the object.
        options: the synthesis options.
        circle: the full circle's step and overlap (used when ``job.thetas`` is None).
        records: the seed pairs' correspondences of a group's objects
            (:func:`synthesize_group`), this object's next; None measures them here. Taken
            inside the job, so that the warnings of its elevation fit are its own.

    Returns:
        The views and the warnings raised on the way (a worker's would be lost: the caller
        re-issues them), or the ``ValueError`` that refused the object's seeds, for the
        caller to name the object.
    """
    with job_warnings(ElevationFallbackWarning) as caught:
        try:
            geometry = None if records is None else next(records)
            if job.thetas is None:
                out = synthesize_circle(
                    job.seeds, circle.step, options, job.masks, circle.overlap, geometry=geometry
                )
            else:
                geo = None if geometry is None else list(geometry)
                out = synthesize_views(
                    job.seeds, job.alpha, job.thetas, options, geometry=geo, masks=job.masks
                )
        except ValueError as exc:
            return exc
    return out, [(str(w.message), w.category, w.filename, w.lineno) for w in caught]


def synthesize_group(jobs: list[ObjectJob], options: SynthesisOptions, circle: Circle) -> list[Outcome]:
    """:func:`synthesize_object` of each job, the seed pairs' flows of all of them in
    shared calls where the jobs share their seeds' angles (the same views). From an object
    whose seeds are refused on, each object is synthesized alone, so that the error is
    its own."""
    records = None
    if all(j.alpha == jobs[0].alpha and (j.thetas is None) == (jobs[0].thetas is None) for j in jobs):
        try:
            records = _group_records(jobs, options)
        except ValueError:
            records = None
    return each_or_alone(
        jobs,
        records,
        lambda job, shared: synthesize_object(job, options, circle, shared),
    )


def _group_records(jobs: list[ObjectJob], options: SynthesisOptions) -> Iterator[list[PairGeometry]]:
    """Each object's seed-pair records, the flows of the group in shared calls: its pairs
    α apart, or for the full circle its M pairs (seeds k and k + 1 mod M)."""
    first = jobs[0]
    if first.thetas is not None:
        return iter_object_geometries([j.seeds for j in jobs], first.alpha, options, [j.masks for j in jobs])
    m = first.seeds.shape[0]
    pairs = iter_object_geometries(
        [j.seeds[[k, (k + 1) % m]] for j in jobs for k in range(m)],
        360.0 / m,
        options,
        [None if j.masks is None else j.masks[[k, (k + 1) % m]] for j in jobs for k in range(m)],
    )
    return ([next(pairs)[0] for _ in range(m)] for _ in jobs)


def _own_outcomes(outcomes: list[Outcome]) -> list[Outcome]:
    """A worker process's outcomes with their views copied out of shared memory."""
    return [o if isinstance(o, ValueError) else (own_views(o[0]), o[1]) for o in outcomes]


def object_galleries(
    jobs: Iterable[ObjectJob],
    names: Iterable[Hashable],
    options: SynthesisOptions,
    circle: Circle,
    *,
    workers: int = 0,
    kind: str = "thread",
    group: int = 1,
) -> Iterator[tuple[Hashable, SynthesizedViews]]:
    """``(name, views)`` per object, in order: :func:`synthesize_object` of each job over
    ``workers`` threads or processes (:func:`~torch_eigview.scale.parallel.map_ordered`;
    0: in this thread), ``group`` objects to a pool job (:func:`synthesize_group`).

    Args:
        jobs: the objects' jobs, read lazily.
        names: the objects' names, one per job (a progress bar over them advances as the
            objects come back).
        options: the synthesis options.
        circle: the full circle's step and overlap, for jobs without ``thetas``.
        workers: worker threads or processes; 0 synthesizes in this thread.
        kind: ``"thread"`` or ``"process"`` (:data:`~torch_eigview.scale.parallel.KINDS`).
        group: objects per pool job.

    Raises:
        ValueError: an object's seeds refused, the message naming the object (the pool
            then closes). Each object's warnings are re-issued with the object named once
            the pool has closed, under the caller's own warning filters.
    """
    copy = workers > 0 and kind == "process"
    results = map_ordered(
        synthesize_group,
        ((g, options, circle) for g in grouped((j.owned() if copy else j for j in jobs), group)),
        workers,
        finish=_own_outcomes,
        kind=kind,
        always=(ElevationFallbackWarning,),
    )
    caught_all: list[CaughtWarning] = []
    with contextlib.closing(results):  # an error here ends the pool (and its warning routing)
        outcomes = (outcome for group_outcomes in results for outcome in group_outcomes)
        for name, outcome in zip(names, outcomes, strict=True):
            shown = repr(name) if isinstance(name, str) else name  # a file's name may hold anything
            if isinstance(outcome, ValueError):  # e.g. a flow that cannot match this object's seeds
                raise ValueError(f"object {shown}: synthesis failed: {outcome}") from outcome
            out, caught = outcome
            for message, category, filename, lineno in caught:
                if issubclass(category, ElevationFallbackWarning):
                    message = f"object {shown}: {message}"
                caught_all.append((message, category, filename, lineno))
            yield name, out
    for message, category, filename, lineno in caught_all:
        warnings.warn_explicit(message, category, filename, lineno)
