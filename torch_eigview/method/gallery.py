"""The eigenspace, layer and recognizer of a gallery that arrives one object at a time.

:class:`~torch_eigview.method.FewViewEigenspace` synthesizes its gallery object by object
and hands each object's views to a :class:`GalleryFit`. A gallery of at most
``max_views`` views is held and fitted at once (:class:`~torch_eigview.decomposition.Eigenspace`,
the exact eigenspace); a larger one is merged as it comes, a few hundred views at a time
(:class:`~torch_eigview.decomposition.incremental.IncrementalEigenspace`), so that memory
is bounded by one object's views, a merge block and the model, not by the number of
objects; the recognizer keeps only the gallery's coordinates. The views held out to
calibrate rejection are kept whole when the gallery is, and otherwise at most
``max_views // 4`` of them in all, spread evenly over each object's.
"""

from __future__ import annotations

import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.incremental import IncrementalEigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.geometry.angles import wrap_degrees
from torch_eigview.method.inputs import Params
from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer
from torch_eigview.scale.ranks import gather_in_rank_order, world
from torch_eigview.scale.thread_policy import eigen_flops, for_products

__all__ = ["GalleryFit", "held_out_quota"]

Space = Eigenspace | KernelEigenspace | IncrementalEigenspace


def held_out_quota(max_views: int, n_objects: int) -> int:
    """Held-out views kept per object when the gallery is merged: ``max_views // 4`` in all."""
    return max(1, (max_views // 4) // max(1, n_objects))


class GalleryFit:
    """Collects a gallery object by object, then fits its eigenspace and recognizer.

    Args:
        params: the estimator's validated hyperparameters.
        n_views: the gallery's views in all (known before synthesis), which decides
            between holding them (at most ``params.max_views``, or a kernel eigenspace)
            and merging them.
        n_objects: the objects, for the held-out views' share per object.
    """

    def __init__(self, params: Params, n_views: int, n_objects: int) -> None:
        self.params = params
        self.merged = params.kernel is None and n_views > params.max_views
        self.views: list[torch.Tensor] = []  # held (exact) or waiting for a merge (merged)
        self.waiting = 0
        self.labels: list[int] = []
        self.poses: list[float] = []
        self.held_out: list[torch.Tensor] = []
        self.quota = held_out_quota(params.max_views, n_objects)
        self.model = (
            IncrementalEigenspace(params.n_components, max_rank=params.max_rank, keep_codes=True)
            if self.merged
            else None
        )
        self.image_shape: tuple[int, int, int] | None = None
        # A rank's model is merged with the others' at the end: in float64, whose codes
        # survive that merge exactly (a float32 basis would round them 1e-4 apart).
        self.ranked = world()[1] > 1
        self.dtype: torch.dtype | None = None

    def add(self, views: torch.Tensor, label: int, poses: list[float], held_out: torch.Tensor | None) -> None:
        """One object's (T, C, H, W) gallery views, their label and T poses (degrees), and its
        views held out for rejection (or None)."""
        c, h, w = views.shape[1:]
        self.image_shape = (c, h, w)
        self.dtype = views.dtype
        self.labels += [label] * len(poses)
        self.poses += poses
        if held_out is not None and held_out.shape[0]:
            if self.merged and held_out.shape[0] > self.quota:  # evenly spread over the object's
                pick = torch.linspace(0, held_out.shape[0] - 1, self.quota).round().long().unique()
                held_out = held_out[pick].clone()
            self.held_out.append(held_out)
        if self.model is None:
            self.views.append(views)
            return
        self.views.append(self.prepared(views))
        self.waiting += views.shape[0]
        if self.waiting >= self.params.max_rank:  # a block of about the model's rank: the cheapest merge
            self._merge()

    def prepared(self, views: torch.Tensor) -> torch.Tensor:
        """(T, N) rows as the eigenspace takes them: unit norm, or as they are."""
        return unit_rows(views) if self.params.unit_norm else views.flatten(1)

    def _merge(self) -> None:
        assert self.model is not None
        if self.views:
            block = torch.cat(self.views)
            self.views = []  # the pieces go before the merge, not after it: one copy held
            block = block.double() if self.ranked else block
            rank = self.params.max_rank
            # The merge's products: the block's Gram, its coordinates in the basis and the new basis.
            flops = block.shape[1] * (block.shape[0] + rank) ** 2
            with torch.no_grad(), for_products(flops):
                self.model.partial_fit(block)
        self.views, self.waiting = [], 0

    def gather(self) -> None:
        """Makes the galleries of every rank of the process group this one, in rank order
        (a no-op without a group): a held gallery by its views, a merged one by its
        eigenspace model (:meth:`IncrementalEigenspace.merge`), with the labels, poses and
        held-out views. Every rank then holds what one process fitting every object would."""
        parts = gather_in_rank_order(self._portable())
        if len(parts) == 1:
            return
        first = next(p for p in parts if p["image_shape"] is not None)
        self.image_shape = first["image_shape"]
        self.labels = [label for p in parts for label in p["labels"]]
        self.poses = [pose for p in parts for pose in p["poses"]]
        self.held_out = [v for p in parts for v in p["held_out"]]
        if self.model is None:
            self.views = [v for p in parts for v in p["views"]]
            return
        model = IncrementalEigenspace(
            self.params.n_components, max_rank=self.params.max_rank, keep_codes=True
        )
        for p in parts:
            model.merge(p["model"])
        self.model = model.report_as(first["dtype"])

    def _portable(self) -> dict[str, object]:
        """This rank's gallery on the CPU, for :func:`gather_in_rank_order`."""
        if self.model is not None:
            self._merge()  # the views still waiting join the model first
        cpu = lambda xs: [x.cpu() for x in xs]  # noqa: E731
        return {
            "image_shape": self.image_shape,
            "dtype": self.dtype,
            "labels": self.labels,
            "poses": self.poses,
            "held_out": cpu(self.held_out),
            "views": cpu(self.views) if self.model is None else [],
            "model": self.model,
        }

    def finish(
        self, names: list[str] | None
    ) -> tuple[Space, EigenProjection | KernelProjection, NearestNeighborRecognizer]:
        """The eigenspace, its frozen layer and the nearest-neighbour recognizer."""
        assert self.image_shape is not None
        params, shape = self.params, self.image_shape
        labels = torch.tensor(self.labels)
        projection: EigenProjection | KernelProjection
        space: Space
        with torch.no_grad():
            if self.model is not None:
                self._merge()
                space = self.model
                projection = space.to_module(unit_norm=params.unit_norm, image_shape=shape)
                codes = space.codes_
                poses = wrap_degrees(torch.tensor(self.poses, dtype=codes.dtype))
                return space, projection, NearestNeighborRecognizer(projection, codes, labels, poses, names)
            x = torch.cat(self.views)
            x_fit = self.prepared(x)
            if params.kernel is None:
                # A command's policy gives a large Gram product the idle CPUs (a no-op in library use).
                with for_products(eigen_flops(*x_fit.shape)):
                    space = linear = Eigenspace(params.n_components).fit(x_fit)
                projection = linear.to_module(unit_norm=params.unit_norm, image_shape=shape)
            else:
                kspace = KernelEigenspace(
                    params.n_components, kernel=params.kernel, gamma=params.gamma, degree=params.degree
                )
                space = kspace.fit(x_fit.reshape(-1, *shape))
                projection = kspace.to_module(unit_norm=params.unit_norm)
            poses = wrap_degrees(torch.tensor(self.poses, dtype=x.dtype))
            return (
                space,
                projection,
                NearestNeighborRecognizer.from_views(projection, x, labels, poses, names),
            )
