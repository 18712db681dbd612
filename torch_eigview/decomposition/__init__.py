"""Decomposition: the eigenspace estimators (in memory, kernel, streaming, incremental) over one
internal linear-algebra core, :mod:`torch_eigview.decomposition.linalg` (not re-exported).
"""

from __future__ import annotations

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.incremental import IncrementalEigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.decomposition.streaming import BlockSource, StreamingEigenspace, blocks_of

__all__ = [
    "BlockSource",
    "Eigenspace",
    "IncrementalEigenspace",
    "KernelEigenspace",
    "StreamingEigenspace",
    "blocks_of",
]
