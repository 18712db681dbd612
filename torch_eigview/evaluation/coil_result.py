"""The outcome of one COIL experiment (:class:`~torch_eigview.evaluation.coil.CoilExperiment`)
and its JSON record."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = ["CoilResult"]


@dataclass
class CoilResult:
    """Outcome of one experiment; ``to_json()`` gives the documented JSON record."""

    accuracy: float
    per_object: dict[int, float]
    pose_mae_deg: float
    n_test: int
    n_train_views: int
    seconds: dict[str, float]
    recognizer: NearestNeighborRecognizer
    elevations: dict[int, list[float]] = field(default_factory=dict)
    pose_median_deg: float = math.nan

    def to_json(self) -> dict[str, object]:
        """The record: accuracy, per_object, n_test, n_train_views, seconds, and the pose
        error of the correctly recognized views (``pose_mae_deg`` and ``pose_error_deg``
        with its mean and median; null when no view is recognized)."""

        def finite(value: float) -> float | None:
            return value if math.isfinite(value) else None

        return {
            "accuracy": self.accuracy,
            "per_object": {str(k): v for k, v in self.per_object.items()},
            "pose_mae_deg": finite(self.pose_mae_deg),
            "pose_error_deg": {"mean": finite(self.pose_mae_deg), "median": finite(self.pose_median_deg)},
            "n_test": self.n_test,
            "n_train_views": self.n_train_views,
            "seconds": self.seconds,
        }
