"""Scale: block sources on disk, the distributed fit and per-object worker processes."""

from __future__ import annotations

from torch_eigview.scale.distributed import fit_distributed
from torch_eigview.scale.parallel import available_cpus, synthesize_objects
from torch_eigview.scale.view_cache import ViewCache

__all__ = ["ViewCache", "available_cpus", "fit_distributed", "synthesize_objects"]
