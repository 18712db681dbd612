"""Scale: block sources on disk, the distributed fit, per-object worker processes and threads."""

from __future__ import annotations

from torch_eigview.scale.distributed import fit_distributed
from torch_eigview.scale.parallel import available_cpus, synthesize_objects
from torch_eigview.scale.thread_policy import default_threads, threads
from torch_eigview.scale.view_cache import ViewCache

__all__ = [
    "ViewCache",
    "available_cpus",
    "default_threads",
    "fit_distributed",
    "synthesize_objects",
    "threads",
]
