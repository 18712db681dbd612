"""The COIL experiment's geometric pose: each recognized view measured against the seed
views of the object it was recognized as (:func:`~torch_eigview.synthesis.seed_pair_poses`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.datasets import CoilFolder
from torch_eigview.synthesis import SynthesisOptions
from torch_eigview.synthesis.view_pose import seed_pair_poses

__all__ = ["SeedPoses"]


@dataclass(frozen=True)
class SeedPoses:
    """``(views, labels, rough poses) → poses``, :func:`~torch_eigview.evaluation.scoring.score`'s
    ``pose_fn``: every view against the seed views of the object it is labelled as.

    Attributes:
        folder: the images (the seeds are read from it, once per object and call).
        seed_poses: the seed views' poses in degrees, any order.
        closed: the seeds go round the whole circle (the full-circle experiment).
        options: the synthesis options (the flow and its settings).
    """

    folder: CoilFolder
    seed_poses: Sequence[float]
    closed: bool
    options: SynthesisOptions

    def __post_init__(self) -> None:
        if self.closed and len(self.seed_poses) < 3:
            raise ValueError(
                f"the geometric pose needs at least 3 seeds round the circle, got {len(self.seed_poses)}: "
                "seeds 180 degrees apart leave Eq. 2 singular"
            )

    def __call__(self, views: torch.Tensor, labels: torch.Tensor, rough: torch.Tensor) -> torch.Tensor:
        """(N,) poses in degrees for (N, C, H, W) ``views``, their (N,) labels and rough poses."""
        poses = sorted(self.seed_poses)
        out = rough.double().clone()
        for label in labels.unique().tolist():
            sel = (labels == label).nonzero()[:, 0]
            seeds = self.folder.images(int(label), poses)
            refined = seed_pair_poses(
                views[sel.to(views.device)],
                rough[sel],
                seeds,
                poses,
                closed=self.closed,
                options=self.options,
            )
            out[sel] = refined.to(out.device)
        return out.to(rough.dtype)
