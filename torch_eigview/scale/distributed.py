"""Eigenspace construction over ``torch.distributed``: objects sharded over ranks.

Each rank produces (synthesizes, loads) the views of its own objects, a (P_r, N) shard; the
eigenspace of all P = Σ_r P_r views comes out identical on every rank:

- ``solver="exact"`` (default): the mean by ``all_reduce``; the P×P Gram matrix of the
  centred views by broadcasting each rank's shard in turn (rank r fills its rows
  Xc_r Xc_sᵀ, memory: its shard plus one other), then one ``all_reduce``; every rank runs
  the same float64 ``eigh``; the components Λ^(−1/2) Σ_r V_rᵀ Xc_r by ``all_reduce`` of
  (k, N) partial sums. Equals :class:`~torch_eigview.decomposition.eigenspace.Eigenspace` on the
  stacked views up to rounding (to the subspace solver's tolerance where its "auto" takes
  that solver: an int k with P and N both at least 4096).
- ``solver="randomized"``: the range finder of :mod:`torch_eigview.decomposition.streaming`, with
  Y = Σ_r Xc_rᵀ Ω_r reduced by ``all_reduce`` (N × l per pass); Ω's rows are drawn by
  global view number, so the result equals the single-process ``StreamingEigenspace``
  with the same seed. Communication N·l per pass instead of the shards.

Bad input (a rank without views, different view sizes or dtypes across ranks) is found by
one ``all_gather_object`` of each rank's metadata before any other collective, so every
rank raises the same ``ValueError`` instead of hanging; the process group's ``timeout``
(``init_process_group(timeout=...)``) ends a collective whose peer died.

The repository's ``benchmarks/bench_distributed.py`` runs it on COIL-20 under torchrun
(gloo on CPU, nccl where CUDA is available)::

    torchrun --nproc_per_node 2 benchmarks/bench_distributed.py --root ../shared/data/coil-20-proc --alpha 5
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import torch
import torch.distributed as dist

from torch_eigview.check import check_n_components
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.linalg import (
    EigenFit,
    check_oversample,
    leading_eigenpairs,
    oversample_for,
    randomized_passes,
    sketch_components,
    sketch_matrix,
)

__all__ = ["fit_distributed"]

_SOLVERS = ("exact", "randomized")


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


def _shard_layout(
    views: object, rank: int, group: dist.ProcessGroup | None, params: dict[str, object]
) -> tuple[list[int], tuple[int, ...]]:
    """Every rank's view count and the common view shape, from one ``all_gather_object``
    that also carries each rank's fit ``params`` (they must be rank 0's).

    Raises:
        ValueError: on every rank alike, when any rank's views are bad or differ in view
            shape or dtype from rank 0's, a parameter differs from rank 0's, or P < 2 over
            all ranks.
    """
    problem = _local_problem(views)
    meta = None
    if problem is None:
        assert isinstance(views, torch.Tensor)
        meta = (int(views.shape[0]), tuple(int(s) for s in views.shape[1:]), str(views.dtype))
    gathered: list[object] = [None] * dist.get_world_size(group)
    _collective(
        rank,
        "the all_gather of the shards' shapes",
        dist.all_gather_object,
        gathered,
        (problem, meta, params),
        group=group,
    )
    records: list[tuple[str | None, tuple[int, tuple[int, ...], str] | None, dict[str, object]]]
    records = gathered  # type: ignore[assignment]
    errors = [f"rank {r}: {p}" for r, (p, _, _) in enumerate(records) if p is not None]
    # Differing parameters would fail later in a collective of another size (SIGABRT).
    errors += [
        f"rank {r}: {key}={value!r} differs from rank 0's {records[0][2][key]!r}"
        for r, (_, _, theirs) in enumerate(records)
        for key, value in theirs.items()
        if value != records[0][2][key]
    ]
    if errors:
        raise ValueError("fit_distributed got bad views: " + "; ".join(errors))
    metas = [m for _, m, _ in records if m is not None]
    first = metas[0]
    for r, m in enumerate(metas):
        if m[1:] != first[1:]:
            raise ValueError(
                f"fit_distributed needs the same view shape and dtype on every rank: rank 0 has "
                f"(P_r, {', '.join(map(str, first[1]))}) {first[2]}, rank {r} has (P_r, {', '.join(map(str, m[1]))}) {m[2]}"
            )
    counts = [m[0] for m in metas]
    if sum(counts) < 2:
        raise ValueError(f"fit_distributed needs at least 2 views over all ranks, got P={sum(counts)}")
    return counts, first[1]


def _exact(
    xc: torch.Tensor,
    counts: list[int],
    rank: int,
    group: dist.ProcessGroup | None,
    n_components: int | float,
    mean64: torch.Tensor,
    all_reduce: Callable[[torch.Tensor], torch.Tensor],
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Eigenvalues (k,), components (k, N) and trace () of all ranks' views from this rank's
    centred (P_r, N) shard ``xc``: the Gram matrix by shard broadcasts, then one eigh."""
    n_views, n_features = sum(counts), xc.shape[1]
    offsets = [sum(counts[:r]) for r in range(len(counts))]
    lo, hi = offsets[rank], offsets[rank] + counts[rank]
    gram = torch.zeros(n_views, n_views, dtype=torch.float64, device=xc.device)
    for src in range(len(counts)):
        other = xc if src == rank else xc.new_empty(counts[src], n_features)
        root = dist.get_global_rank(group, src) if group else src
        _collective(
            rank, f"the broadcast of rank {src}'s shard", dist.broadcast, other, src=root, group=group
        )
        gram[lo:hi, offsets[src] : offsets[src] + counts[src]] = (xc @ other.T).double()
        del other
    gram = all_reduce(gram)
    gram = (gram + gram.T) / 2  # the two halves came from different ranks' products
    eigvals, basis, total = leading_eigenpairs(gram, n_components, mean64, n_views, xc.dtype, "views")
    partial = (basis[lo:hi].T.to(xc.dtype) @ xc).double()
    return eigvals, all_reduce(partial) / eigvals.sqrt()[:, None], total


def fit_distributed(
    views: torch.Tensor,
    n_components: int | float = 15,
    *,
    solver: str = "exact",
    group: dist.ProcessGroup | None = None,
    oversample: int | str = "auto",
    n_iter: int = 2,
    seed: int = 0,
    method: str | None = None,
) -> Eigenspace:
    """Fits one eigenspace over the views of all ranks; call it on every rank.

    Args:
        views: this rank's (P_r, N) or (P_r, C, H, W) views, float32/float64, P_r >= 1;
            the same view shape and dtype on every rank; P = Σ_r P_r >= 2.
        n_components: k or an energy fraction, as for ``Eigenspace``.
        solver: ``"exact"`` (Gram by shard broadcasts) or ``"randomized"`` (range finder),
            as ``StreamingEigenspace``'s ``solver``.
        group: the process group (default: the world).
        oversample, n_iter, seed: the randomized method's l = k + ``oversample`` (an int
            >= 0, or "auto":
            :data:`~torch_eigview.decomposition.linalg.RANDOMIZED_OVERSAMPLE`, 10, as
            ``StreamingEigenspace``'s), power iterations and the seed of Ω.
        method: deprecated, the old name of ``solver``; it warns and sets ``solver``.

    Returns:
        A fitted ``Eigenspace`` (:meth:`Eigenspace.from_fit`), the same on every rank.

    Raises:
        RuntimeError: torch.distributed is not initialized, or a collective failed because
            a peer rank left.
        TimeoutError: a collective did not complete within the process group's timeout
            (``init_process_group(timeout=...)``): a rank stalled or died.
        ValueError: on every rank, when any rank has no views, bad or non-finite views, a
            view shape or dtype or a parameter (``n_components``, ``solver``, ``oversample``,
            ``n_iter``, ``seed``) different from rank 0's; an ``oversample`` other than
            "auto" or an int >= 0 (TypeError for one of another type); ``n_components``
            above the rank, or an energy fraction the randomized sketch does not reach.
    """
    if not dist.is_available() or not dist.is_initialized():
        raise RuntimeError("fit_distributed needs torch.distributed initialized (init_process_group)")
    if method is not None:
        warnings.warn(
            "fit_distributed(method=...) is deprecated: the argument is named solver, as "
            "StreamingEigenspace's; give solver=...",
            DeprecationWarning,
            stacklevel=2,
        )
        if solver != "exact":
            raise TypeError(f"give solver={solver!r} or the deprecated method={method!r}, not both")
        solver = method
    n_components = check_n_components(n_components)
    if solver not in _SOLVERS:
        raise ValueError(f"solver={solver!r} must be one of {_SOLVERS}")
    rank = dist.get_rank(group)
    params: dict[str, object] = {
        "n_components": n_components,
        "solver": solver,
        "oversample": oversample,
        "n_iter": n_iter,
        "seed": seed,
    }
    counts, feature_shape = _shard_layout(views, rank, group, params)
    # Checked once every rank is known to hold the same value, so that all raise alike.
    oversample = check_oversample(oversample)
    n_views = sum(counts)
    image_shape = (feature_shape[0], feature_shape[1], feature_shape[2]) if len(feature_shape) == 3 else None
    dtype = views.dtype
    x = views.detach().reshape(views.shape[0], -1)

    def all_reduce(t: torch.Tensor) -> torch.Tensor:
        _collective(rank, "an all_reduce", dist.all_reduce, t, group=group)
        return t

    with torch.no_grad():
        mean64 = all_reduce(x.double().sum(dim=0)) / n_views
        if solver == "randomized":
            omega = sketch_matrix(
                n_components, oversample_for(oversample, "randomized"), n_views, x.shape[1], seed, x.device
            )
            q, z, total = randomized_passes(
                [x], mean64, omega, n_iter, all_reduce, row_offset=sum(counts[:rank])
            )
            eigvals, components = sketch_components(
                q, z, total, n_components, mean64, n_views, dtype, "views"
            )
        else:
            xc = x - mean64.to(dtype)
            eigvals, components, total = _exact(xc, counts, rank, group, n_components, mean64, all_reduce)
    fit = EigenFit.from_eigenpairs(mean64, components, eigvals, total, n_views, image_shape, dtype)
    return Eigenspace.from_fit(fit, n_components)
