"""The whole method as one estimator: seed views per object in, eigenspace and gallery out."""

from __future__ import annotations

from torch_eigview.geometry.angles import AROUND_SEEDS
from torch_eigview.method.estimator import FewViewEigenspace
from torch_eigview.method.inputs import ALL_COMPONENTS, resolve_components
from torch_eigview.method.memory import MemoryBudgetError
from torch_eigview.method.rejection import calibrate_rejection, estimate_reject_rate

__all__ = [
    "ALL_COMPONENTS",
    "AROUND_SEEDS",
    "FewViewEigenspace",
    "MemoryBudgetError",
    "calibrate_rejection",
    "estimate_reject_rate",
    "resolve_components",
]
