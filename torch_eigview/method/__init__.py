"""The whole method as one estimator: seed views per object in, eigenspace and gallery out."""

from __future__ import annotations

from torch_eigview.method.estimator import FewViewEigenspace
from torch_eigview.method.inputs import ALL_COMPONENTS, resolve_components

__all__ = ["ALL_COMPONENTS", "FewViewEigenspace", "resolve_components"]
