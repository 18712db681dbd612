"""The recognition protocol of the paper's experiments (Sec. 5.1, Fig. 2; Sec. 5.2, Fig. 4(b)).

Every experiment runs the same three steps, whatever made its gallery:

1. :func:`stack_gallery`: the gallery views of all objects in one batch, with their labels
   and poses;
2. :func:`build_recognizer`: one eigenspace over all of them (each view scaled to unit L2
   norm: Murase and Nayar's brightness normalization), the projection layer that applies
   it, and the nearest-neighbour recognizer over the gallery's coefficients;
3. :func:`score`: each object's test views recognized; the accuracy over all of them and
   per object, and the mean absolute pose error of the correctly recognized ones.

The COIL experiment (:mod:`torch_eigview.evaluation.coil`) and the synthetic one
(:mod:`torch_eigview.apps.demo`) differ only in their galleries and test views.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Hashable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

import torch

from torch_eigview.check import check_int
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.geometry.angles import angle_range, wrap_degrees
from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer
from torch_eigview.scale.parallel import map_ordered
from torch_eigview.scale.thread_policy import eigen_flops, for_products

__all__ = [
    "Score",
    "angle_range",
    "build_recognizer",
    "fit_projection",
    "score",
    "stack_gallery",
    "wrap_degrees",
]

K = TypeVar("K", bound=Hashable)


def stack_gallery(
    blocks: Iterable[tuple[torch.Tensor, int, Sequence[float]]],
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """All objects' gallery views in one batch.

    Args:
        blocks: per object ``(views, label, poses)``: (T_i, C, H, W) views, the object's
            integer label and its T_i poses in degrees.

    Returns:
        ``(views, labels, poses)``: (P, C, H, W) views, (P,) int64 labels and (P,) poses
        of the views' dtype, P = Σ T_i, in the order of ``blocks``.
    """
    views: list[torch.Tensor] = []
    labels: list[int] = []
    poses: list[float] = []
    for block, label, angles in blocks:
        views.append(block)
        labels += [label] * len(angles)
        poses += angles
    x = torch.cat(views)
    return x, torch.tensor(labels), torch.tensor(poses, dtype=x.dtype)


def fit_projection(
    views: torch.Tensor,
    components: int | float,
    *,
    unit_norm: bool = True,
    kernel: str | None = None,
    gamma: float | str | None = None,
) -> EigenProjection | KernelProjection:
    """The eigenspace of the gallery views as a frozen projection layer.

    Args:
        views: (P, C, H, W) gallery views.
        components: eigenspace dimension k (int) or energy fraction (float in (0, 1)).
        unit_norm: scale every view to unit L2 norm, before the fit and in the layer.
        kernel: None for the linear eigenspace (the paper's), or a
            :class:`~torch_eigview.decomposition.kernel.KernelEigenspace` kernel.
        gamma: the kernel's γ (see :class:`~torch_eigview.decomposition.kernel.KernelEigenspace`).

    Returns:
        An :class:`~torch_eigview.nn.projection.EigenProjection` (linear) or a
        :class:`~torch_eigview.nn.kernel_projection.KernelProjection` taking (B, C, H, W) views.
    """
    c, h, w = views.shape[1:]
    x_fit = unit_rows(views) if unit_norm else views.flatten(1)
    if kernel is None:
        with for_products(eigen_flops(*x_fit.shape)):
            space = Eigenspace(components).fit(x_fit)
        return EigenProjection(
            space.mean_, space.components_, space.eigenvalues_, (c, h, w), unit_norm=unit_norm
        )
    kspace = KernelEigenspace(components, kernel=kernel, gamma=gamma)
    return kspace.fit(x_fit.reshape(-1, c, h, w)).to_module(unit_norm=unit_norm)


def build_recognizer(
    views: torch.Tensor,
    labels: torch.Tensor,
    poses: torch.Tensor,
    components: int | float,
    *,
    unit_norm: bool = True,
    kernel: str | None = None,
    gamma: float | str | None = None,
    label_names: list[str] | None = None,
) -> NearestNeighborRecognizer:
    """The nearest-neighbour recognizer over the eigenspace of the gallery (:func:`fit_projection`).

    Args:
        views: (P, C, H, W) gallery views.
        labels: (P,) their labels.
        poses: (P,) their poses in degrees.
        components, unit_norm, kernel, gamma: as :func:`fit_projection`'s.
        label_names: names of the labels 0, 1, …, or None.

    Example:
        >>> views = torch.rand(6, 1, 8, 8)
        >>> labels = torch.tensor([0, 0, 0, 1, 1, 1])
        >>> rec = build_recognizer(views, labels, torch.zeros(6), 3)
        >>> rec.predict(views).labels.tolist()
        [0, 0, 0, 1, 1, 1]
    """
    projection = fit_projection(views, components, unit_norm=unit_norm, kernel=kernel, gamma=gamma)
    return NearestNeighborRecognizer.from_views(projection, views, labels, poses, label_names)


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
