"""Eigenspace construction over ``torch.distributed``: objects sharded over ranks.

Each rank produces (synthesizes, loads) the views of its own objects, a (P_r, N) shard; the
eigenspace of all P = Σ_r P_r views comes out identical on every rank:

- ``method="exact"`` (default): the mean by ``all_reduce``; the P×P Gram matrix of the
  centred views by broadcasting each rank's shard in turn (rank r fills its rows
  Xc_r Xc_sᵀ, memory: its shard plus one other), then one ``all_reduce``; every rank runs
  the same float64 ``eigh``; the components Λ^(−1/2) Σ_r V_rᵀ Xc_r by ``all_reduce`` of
  (k, N) partial sums. Equals :class:`~torch_eigview.decomposition.eigenspace.Eigenspace` on the
  stacked views up to rounding.
- ``method="randomized"``: the range finder of :mod:`torch_eigview.decomposition.streaming`, with
  Y = Σ_r Xc_rᵀ Ω_r reduced by ``all_reduce`` (N × l per pass); Ω's rows are drawn by
  global view number, so the result equals the single-process ``StreamingEigenspace``
  with the same seed. Communication N·l per pass instead of the shards.

Bad input (a rank without views, different view sizes or dtypes across ranks) is found by
one ``all_gather_object`` of each rank's metadata before any other collective, so every
rank raises the same ``ValueError`` instead of hanging; the process group's ``timeout``
(``init_process_group(timeout=...)``, 30 s in ``eigview``'s distributed command) ends a collective whose peer died.

Run it on COIL-20 (gloo on CPU, nccl where CUDA is available)::

    torchrun --nproc_per_node 2 -m torch_eigview.apps.distributed --root ../shared/data/coil-20-proc --alpha 5
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.distributed as dist

from torch_eigview.check import check_n_components
from torch_eigview.decomposition.eigenspace import Eigenspace, _eigh_descending, _Fit, _flip_signs
from torch_eigview.decomposition.streaming import above_tolerance, randomized_passes, select_k

__all__ = ["fit_distributed"]

_METHODS = ("exact", "randomized")


def _local_problem(views: object) -> str | None:
    if not isinstance(views, torch.Tensor):
        return f"views must be a torch.Tensor, got {type(views).__name__}"
    if views.dtype not in (torch.float32, torch.float64):
        return f"views must have dtype float32 or float64, got {views.dtype}"
    if views.ndim not in (2, 4):
        return f"views must have shape (P_r, N) or (P_r, C, H, W), got shape {tuple(views.shape)}"
    if views.shape[0] == 0:
        return "views holds no views (P_r = 0): every rank needs at least one object"
    if not bool(torch.isfinite(views).all()):
        return "views must be finite, got NaN or infinite values"
    return None


def _collective(rank: int, what: str, fn: Callable[..., object], *args: object, **kwargs: object) -> None:
    """Runs one collective; a timeout or a lost peer becomes a clear error on this rank.

    The process group's ``timeout`` bounds every collective (gloo and nccl raise when it
    passes), so a rank that stalls or dies ends the others' wait with this error instead of
    a hang; the stalled rank, when it comes back, finds its peers gone and raises too.
    """
    try:
        fn(*args, **kwargs)
    except RuntimeError as err:  # DistBackendError, DistNetworkError and gloo's errors
        text = str(err)
        first = text.splitlines()[0] if text else type(err).__name__
        if "timed out" in text.lower() or "timeout" in text.lower():
            raise TimeoutError(
                f"fit_distributed on rank {rank}: {what} did not complete within the process group's "
                f"timeout: a rank stalled or died ({first})"
            ) from err
        if isinstance(err, dist.DistError) or "connection" in text.lower() or "gloo" in text.lower():
            raise RuntimeError(
                f"fit_distributed on rank {rank}: {what} failed, a peer rank left or the group broke ({first})"
            ) from err
        raise


def fit_distributed(
    views: torch.Tensor,
    n_components: int | float = 15,
    *,
    method: str = "exact",
    group: dist.ProcessGroup | None = None,
    oversample: int = 10,
    n_iter: int = 2,
    seed: int = 0,
) -> Eigenspace:
    """Fits one eigenspace over the views of all ranks; call it on every rank.

    Args:
        views: this rank's (P_r, N) or (P_r, C, H, W) views, float32/float64, P_r >= 1;
            the same view shape and dtype on every rank; P = Σ_r P_r >= 2.
        n_components: k or an energy fraction, as for ``Eigenspace``.
        method: ``"exact"`` (Gram by shard broadcasts) or ``"randomized"`` (range finder).
        group: the process group (default: the world).
        oversample, n_iter, seed: the randomized method's l = k + oversample, power
            iterations and the seed of Ω.

    Returns:
        A fitted ``Eigenspace``, the same on every rank.

    Raises:
        RuntimeError: torch.distributed is not initialized, or a collective failed because
            a peer rank left.
        TimeoutError: a collective did not complete within the process group's timeout
            (``init_process_group(timeout=...)``): a rank stalled or died.
        ValueError: on every rank, when any rank has no views, bad or non-finite views, or
            a view shape or dtype different from rank 0's; ``n_components`` above the rank.
    """
    if not dist.is_available() or not dist.is_initialized():
        raise RuntimeError("fit_distributed needs torch.distributed initialized (init_process_group)")
    n_components = check_n_components(n_components)
    if method not in _METHODS:
        raise ValueError(f"method={method!r} must be one of {_METHODS}")
    rank, world = dist.get_rank(group), dist.get_world_size(group)
    problem = _local_problem(views)
    meta = None
    if problem is None:
        meta = (int(views.shape[0]), tuple(int(s) for s in views.shape[1:]), str(views.dtype))
    gathered: list[object] = [None] * world
    _collective(
        rank,
        "the all_gather of the shards' shapes",
        dist.all_gather_object,
        gathered,
        (problem, meta),
        group=group,
    )
    records: list[tuple[str | None, tuple[int, tuple[int, ...], str] | None]] = gathered  # type: ignore[assignment]
    errors = [f"rank {r}: {p}" for r, (p, _) in enumerate(records) if p is not None]
    if errors:
        raise ValueError("fit_distributed got bad views: " + "; ".join(errors))
    metas = [m for _, m in records if m is not None]
    first = metas[0]
    for r, m in enumerate(metas):
        if m[1:] != first[1:]:
            raise ValueError(
                f"fit_distributed needs the same view shape and dtype on every rank: rank 0 has "
                f"(P_r, {', '.join(map(str, first[1]))}) {first[2]}, rank {r} has (P_r, {', '.join(map(str, m[1]))}) {m[2]}"
            )
    counts = [m[0] for m in metas]
    n_views = sum(counts)
    if n_views < 2:
        raise ValueError(f"fit_distributed needs at least 2 views over all ranks, got P={n_views}")
    offsets = [sum(counts[:r]) for r in range(world)]
    lo, hi = offsets[rank], offsets[rank] + counts[rank]
    feature_shape = first[1]
    image_shape = (feature_shape[0], feature_shape[1], feature_shape[2]) if len(feature_shape) == 3 else None
    dtype = views.dtype
    x = views.detach().reshape(views.shape[0], -1)
    n_features = x.shape[1]

    def all_reduce(t: torch.Tensor) -> torch.Tensor:
        _collective(rank, "an all_reduce", dist.all_reduce, t, group=group)
        return t

    with torch.no_grad():
        mean64 = all_reduce(x.double().sum(dim=0)) / n_views
        xc = x - mean64.to(dtype)
        if method == "randomized":
            k_max = n_components if isinstance(n_components, int) else min(n_views, n_features)
            width = min(k_max + oversample, n_views, n_features)
            gen = torch.Generator(device="cpu").manual_seed(seed)
            omega = torch.randn(n_views, width, generator=gen, dtype=torch.float64).to(x.device)
            q, z, total = randomized_passes([x], mean64, omega, n_iter, all_reduce, row_offset=lo)
            _, s, wt = torch.linalg.svd(z, full_matrices=False)
            eigvals = s.square()
            k = select_k(
                n_components, above_tolerance(eigvals, total, mean64, n_views, dtype), total, "views", n_views
            )
            components = wt[:k] @ q.T
        else:
            gram = torch.zeros(n_views, n_views, dtype=torch.float64, device=x.device)
            for src in range(world):
                other = xc if src == rank else xc.new_empty(counts[src], n_features)
                root = dist.get_global_rank(group, src) if group else src
                _collective(
                    rank, f"the broadcast of rank {src}'s shard", dist.broadcast, other, src=root, group=group
                )
                gram[lo:hi, offsets[src] : offsets[src] + counts[src]] = (xc @ other.T).double()
                del other
            gram = all_reduce(gram)
            gram = (gram + gram.T) / 2  # the two halves came from different ranks' products
            top = n_components if isinstance(n_components, int) else None
            eigvals, basis = _eigh_descending(gram, top)
            total = gram.diagonal().sum()
            k = select_k(
                n_components, above_tolerance(eigvals, total, mean64, n_views, dtype), total, "views", n_views
            )
            eigvals = eigvals[:k]
            partial = (basis[lo:hi, :k].T.to(dtype) @ xc).double()
            components = all_reduce(partial) / eigvals.sqrt()[:, None]
    space = Eigenspace(n_components)
    space._state = _Fit(
        mean=mean64.to(dtype),
        components=_flip_signs(components.to(dtype).contiguous()),
        eigenvalues=eigvals[:k].to(dtype),
        ratio=(eigvals[:k] / total).to(dtype),
        n_samples=n_views,
        image_shape=image_shape,
    )
    return space
