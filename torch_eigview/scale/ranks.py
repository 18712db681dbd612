"""Objects split over the ranks of a ``torch.distributed`` process group.

:meth:`~torch_eigview.method.FewViewEigenspace.fit` run on every rank of an initialized
process group (``torchrun --nproc-per-node N``, or ``init_process_group`` by hand)
synthesizes only its own objects, a contiguous share (:func:`object_shard`), and the
ranks' galleries become one (:func:`gather_in_rank_order`): held galleries by their
views, merged ones by their eigenspace models
(:meth:`~torch_eigview.decomposition.IncrementalEigenspace.merge`, exact below the rank
cap). Shares are contiguous and gathered in rank order, so the gallery's views come in
the objects' own order and every rank ends with the model one process would fit: the same
up to rounding below ``max_rank``; past it one process and the ranks each drop their
smallest eigenpairs at other merges, both within the reported truncation bound.

:func:`process_group` starts the default group for a given rank and world size (gloo;
nccl for CUDA work) and ends it; ``eigview fit`` calls it with what torchrun put in its
environment, which only the command reads.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from datetime import timedelta
from typing import Any

import torch.distributed as dist

__all__ = ["gather_in_rank_order", "object_shard", "process_group", "world"]


def world() -> tuple[int, int]:
    """``(rank, world size)`` of the default process group; ``(0, 1)`` without one."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def object_shard(n_objects: int) -> range:
    """This rank's objects: a contiguous share of ``range(n_objects)``, the first ranks
    taking one more where they do not divide evenly; all of them without a group.

    Raises:
        ValueError: more ranks than objects (a rank would have nothing to do).

    Example:
        >>> object_shard(5)
        range(0, 5)
    """
    rank, size = world()
    if size > n_objects:
        raise ValueError(
            f"the process group has {size} ranks for {n_objects} object(s): every rank needs at least one "
            "object; start fewer processes (torchrun --nproc-per-node)"
        )
    base, extra = divmod(n_objects, size)
    start = rank * base + min(rank, extra)
    return range(start, start + base + (1 if rank < extra else 0))


def gather_in_rank_order(value: Any) -> list[Any]:
    """Every rank's ``value`` (any picklable object; tensors on the CPU), in rank order:
    ``[value]`` without a group.

    Raises:
        RuntimeError: a peer rank left or the group broke; TimeoutError: a rank did not
            answer within the group's timeout (``init_process_group(timeout=...)``).
    """
    rank, size = world()
    if size == 1:
        return [value]
    out: list[Any] = [None] * size
    try:
        dist.all_gather_object(out, value)
    except RuntimeError as err:
        first = (str(err).splitlines() or [type(err).__name__])[0]
        if "timeout" in str(err).lower() or "timed out" in str(err).lower():
            raise TimeoutError(
                f"rank {rank}: gathering the ranks' galleries timed out: a rank stalled or died ({first})"
            ) from err
        raise RuntimeError(
            f"rank {rank}: gathering the ranks' galleries failed, a peer rank left ({first})"
        ) from err
    return out


@contextlib.contextmanager
def process_group(rank: int, size: int, backend: str = "gloo", timeout_s: float = 1800.0) -> Iterator[int]:
    """Starts the default process group as ``rank`` of ``size`` (the rendezvous from
    ``MASTER_ADDR`` and ``MASTER_PORT``, torch's ``env://``) when ``size`` > 1 and none is
    running, and ends it on exit; yields the rank (0 alone).

    Args:
        rank, size: this process's rank and the number of processes (torchrun's ``RANK``
            and ``WORLD_SIZE``).
        backend: ``"gloo"`` or ``"nccl"`` (CUDA tensors).
        timeout_s: how long a collective waits for a rank that stalled or died.

    Raises:
        ValueError: a rank outside [0, size), or an unknown backend.
    """
    if backend not in ("gloo", "nccl"):
        raise ValueError(f"backend must be 'gloo' or 'nccl', got {backend!r}")
    if not 0 <= rank < max(size, 1):
        raise ValueError(f"rank={rank} must lie in [0, size={size})")
    if size <= 1 or (dist.is_available() and dist.is_initialized()):
        yield world()[0]
        return
    if not dist.is_available():
        raise RuntimeError(f"size={size} asks for torch.distributed, which this torch build lacks")
    dist.init_process_group(backend, rank=rank, world_size=size, timeout=timedelta(seconds=timeout_s))
    try:
        yield rank
    finally:
        dist.destroy_process_group()
