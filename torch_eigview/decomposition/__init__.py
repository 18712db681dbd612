"""Decomposition: the eigenspace estimators (in memory, kernel, streaming) over one
internal linear-algebra core, :mod:`torch_eigview.decomposition.linalg` (not re-exported).
"""

from __future__ import annotations

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.decomposition.streaming import BlockSource, StreamingEigenspace, blocks_of

__all__ = ["BlockSource", "Eigenspace", "KernelEigenspace", "StreamingEigenspace", "blocks_of"]
