"""``eigview fit`` under ``torchrun``: the default process group from its environment.

torchrun starts N copies of the command with ``RANK``, ``WORLD_SIZE``, ``MASTER_ADDR`` and
``MASTER_PORT`` set; :func:`torchrun_group` turns them into the default process group, in
which :meth:`~torch_eigview.method.FewViewEigenspace.fit` splits the objects over the ranks
(:mod:`torch_eigview.scale.ranks`). The environment is the command's to read, not the
library's.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from datetime import timedelta

import torch.distributed as dist

from torch_eigview.scale.ranks import world

__all__ = ["torchrun_group"]


@contextlib.contextmanager
def torchrun_group(backend: str | None = None, timeout_s: float = 1800.0) -> Iterator[int]:
    """Starts the default process group from ``torchrun``'s environment (``RANK``,
    ``WORLD_SIZE``, ``MASTER_ADDR``, ``MASTER_PORT``) when ``WORLD_SIZE`` > 1 and none is
    running, and ends it on exit; yields this process's rank (0 alone).

    Args:
        backend: ``"gloo"`` (default) or ``"nccl"`` (CUDA tensors).
        timeout_s: how long a collective waits for a rank that stalled or died.

    Raises:
        ValueError: ``WORLD_SIZE`` or ``RANK`` is not an integer, or the backend is unknown.
    """
    size_text = os.environ.get("WORLD_SIZE", "1")
    try:
        size = int(size_text)
        rank = int(os.environ.get("RANK", "0"))
    except ValueError:
        raise ValueError(
            f"WORLD_SIZE={size_text!r} and RANK={os.environ.get('RANK')!r} must be integers (torchrun sets them)"
        ) from None
    backend = backend or "gloo"
    if backend not in ("gloo", "nccl"):
        raise ValueError(f"backend must be 'gloo' or 'nccl', got {backend!r}")
    if size <= 1 or (dist.is_available() and dist.is_initialized()):
        yield world()[0]
        return
    if not dist.is_available():
        raise RuntimeError("WORLD_SIZE > 1 asks for torch.distributed, which this torch build lacks")
    dist.init_process_group(backend, rank=rank, world_size=size, timeout=timedelta(seconds=timeout_s))
    try:
        yield rank
    finally:
        dist.destroy_process_group()
