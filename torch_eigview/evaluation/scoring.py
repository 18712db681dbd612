"""Recognition scored on test views (the paper's Sec. 5.1, Fig. 2 and Sec. 5.2, Fig. 4(b)).

A recognizer (fitted by :class:`~torch_eigview.method.FewViewEigenspace`) recognizes
each object's test views; :func:`score` reports the accuracy over all of them and per
object, and the absolute pose error (mean and median) of the correctly recognized ones.
The COIL experiment (:mod:`torch_eigview.evaluation.coil`), ``eigview demo`` and
``eigview evaluate`` all score this way.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Hashable, Iterable, Iterator
from dataclasses import dataclass
from typing import Generic, TypeVar

import torch

from torch_eigview.check import check_int
from torch_eigview.geometry.angles import wrap_degrees
from torch_eigview.nn.recognition import NearestNeighborRecognizer
from torch_eigview.scale.parallel import map_ordered

__all__ = ["Score", "score"]

K = TypeVar("K", bound=Hashable)


@dataclass(frozen=True)
class Score(Generic[K]):
    """The recognition of the test views.

    Attributes:
        accuracy: correctly recognized test views, % of all.
        per_object: the same per object (in the order the objects were scored).
        pose_mae_deg: mean absolute pose error (degrees) of the correctly recognized
            views; NaN when none is.
        n_test: the number of test views.
        pose_median_deg: median absolute pose error (degrees) of the same views; NaN
            when none is.
    """

    accuracy: float
    per_object: dict[K, float]
    pose_mae_deg: float
    n_test: int
    pose_median_deg: float = math.nan


def score(
    recognizer: NearestNeighborRecognizer,
    tests: Iterable[tuple[K, int, torch.Tensor, torch.Tensor]],
    *,
    wrap: bool = False,
    interpolate_pose: bool = False,
    pose_fn: Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor] | None = None,
    workers: int = 0,
) -> Score[K]:
    """Recognizes every object's test views and scores them.

    Args:
        recognizer: the gallery's recognizer.
        tests: per object ``(key, label, views, poses)``: its key in ``per_object``, its
            label, (T, C, H, W) test views and their (T,) true poses in degrees (of the
            recognizer's dtype). Consumed lazily: one object's views at a time.
        wrap: take pose errors modulo 360° (:func:`wrap_degrees`), for poses that go
            round a turntable.
        interpolate_pose: the pose interpolated on the appearance manifold
            (``recognizer.predict(..., interpolate_pose=True)``), not the nearest view's.
        pose_fn: ``(views (T, C, H, W), labels (T,), poses (T,)) → poses (T,)`` that
            replaces the recognizer's poses (the start it is given) of the correctly
            recognized views, the only ones scored; e.g.
            :class:`~torch_eigview.evaluation.seed_pose.SeedPoses`.
        workers: threads that run ``pose_fn``, one object each at a time, while this
            thread recognizes the next objects (0: all in this thread). Each runs torch
            under the caller's intra-op threads: use them under
            :func:`~torch_eigview.scale.thread_policy.threads` ``(1)``, as the commands
            do (:func:`~torch_eigview.scale.parallel.map_ordered`).
    """
    workers = check_int(workers, "workers", minimum=0)
    per_object: dict[K, float] = {}
    counts = {"ok": 0, "test": 0}

    def recognized() -> Iterator[tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]]:
        # In this thread, in order: map_ordered consumes the jobs here.
        for key, label, views, truth in tests:
            result = recognizer.predict(views, interpolate_pose=interpolate_pose)
            ok = result.labels == label
            per_object[key] = 100.0 * float(ok.double().mean())
            counts["ok"] += int(ok.sum())
            counts["test"] += truth.shape[0]
            # The pose error counts recognized views only; only pose_fn reads their images.
            picked = views[ok.to(views.device)] if pose_fn is not None else views
            yield picked, result.labels[ok], result.poses[ok], truth[ok]

    def pose_error(
        views: torch.Tensor, labels: torch.Tensor, poses: torch.Tensor, truth: torch.Tensor
    ) -> torch.Tensor:
        if pose_fn is not None and poses.numel():
            poses = pose_fn(views, labels, poses)
        diff = poses - truth
        return (wrap_degrees(diff) if wrap else diff).abs()

    jobs = map_ordered(pose_error, recognized(), workers if pose_fn is not None else 0, kind="thread")
    with contextlib.closing(jobs):  # an error ends the pool
        errors = torch.cat(list(jobs))
    n_ok, n_test = counts["ok"], counts["test"]
    return Score(
        accuracy=100.0 * n_ok / n_test,
        per_object=per_object,
        pose_mae_deg=float(errors.mean()) if errors.numel() else math.nan,
        n_test=n_test,
        # The true median (the mean of the two middle values), not torch's lower one.
        pose_median_deg=float(errors.double().quantile(0.5)) if errors.numel() else math.nan,
    )
