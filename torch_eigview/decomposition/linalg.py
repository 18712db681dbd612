"""The decomposition package's internal linear-algebra core.

Every eigenspace the package fits (``Eigenspace``, ``StreamingEigenspace``,
``KernelEigenspace``, ``torch_eigview.scale.fit_distributed``) goes through these, so they
agree to the last bit: the Gram product, the float64 eigensolver, the sign rule, the rank
tolerance, the choice of k, the oversampling of the iterative methods, the randomized
range finder and the fit record :class:`EigenFit`. (Except where ``Eigenspace``'s "auto"
takes the subspace solver of :mod:`torch_eigview.decomposition.subspace`, for an int k
with P and N both at least ``SUBSPACE_MIN``: that fit agrees with the exact ones to its
tolerance, about 2e-6 rad in float32.) The names are public for the ``scale`` layer, not
re-exported by
:mod:`torch_eigview.decomposition`; inputs are trusted (callers validate them).

Convention: a data matrix ``X`` is (P, N), one row per view; ``Xc`` is X minus the mean view.
"""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import torch

from torch_eigview.check import check_int
from torch_eigview.decomposition.eigh import eigh_descending, single_threaded_blas
from torch_eigview.decomposition.subspace import SUBSPACE_OVERSAMPLE

__all__ = [
    "RANDOMIZED_OVERSAMPLE",
    "EigenFit",
    "centred_k",
    "check_oversample",
    "choose_k",
    "eigh_descending",
    "gram",
    "leading_eigenpairs",
    "numerical_rank",
    "oversample_for",
    "peak_signs",
    "randomized_passes",
    "rank_tolerance",
    "single_threaded_blas",
    "sketch_components",
    "sketch_matrix",
]

#: Extra random directions of the randomized range finder by default (``oversample="auto"``
#: with ``solver="randomized"``): l = k + 10. Its passes are fixed (3 + ``n_iter``), so
#: extra directions buy accuracy, not fewer passes, each at a share of every pass's
#: products; Halko, Martinsson and Tropp (2011, Sec. 4.2) find 5 or 10 adequate, and
#: scikit-learn's randomized PCA takes 10 (``n_oversamples``).
RANDOMIZED_OVERSAMPLE = 10


def check_oversample(oversample: object) -> int | str:
    """``oversample`` checked: ``"auto"`` or an int >= 0.

    Raises:
        TypeError: neither a str nor an integer (bool included).
        ValueError: another str, or a negative int.
    """
    if isinstance(oversample, str):
        if oversample != "auto":
            raise ValueError(f"oversample={oversample!r} must be 'auto' or an int >= 0")
        return oversample
    if isinstance(oversample, bool) or not isinstance(oversample, numbers.Integral):
        raise TypeError(
            f"oversample must be 'auto' or an int >= 0, got {type(oversample).__name__} {oversample!r}"
        )
    return check_int(oversample, "oversample", 0)


def oversample_for(oversample: int | str, method: str) -> int:
    """The extra vectors beyond k of ``method``'s block: ``oversample``, or for ``"auto"``
    :data:`~torch_eigview.decomposition.subspace.SUBSPACE_OVERSAMPLE` (35) for
    ``"subspace"`` and :data:`RANDOMIZED_OVERSAMPLE` (10) for ``"randomized"``.

    The two methods use their extra vectors differently: the subspace iteration runs until
    it converges, and a wider block converges in fewer iterations (passes over the data);
    the range finder makes a fixed number of passes, and a wider sketch is more accurate.
    """
    if oversample != "auto":
        return int(oversample)
    return SUBSPACE_OVERSAMPLE if method == "subspace" else RANDOMIZED_OVERSAMPLE


@dataclass(frozen=True)
class EigenFit:
    """A fitted linear eigenspace: what ``Eigenspace`` and ``StreamingEigenspace`` hold."""

    mean: torch.Tensor  # (N,) the mean view
    components: torch.Tensor  # (k, N) orthonormal eigenvectors as rows, by decreasing eigenvalue
    eigenvalues: torch.Tensor  # (k,) λ of the centred scatter Xcᵀ Xc, descending
    ratio: torch.Tensor  # (k,) each λ over the sum of all eigenvalues (explained variance ratio)
    n_samples: int  # P, the number of views fitted
    image_shape: tuple[int, int, int] | None  # (C, H, W) of a view, or None

    @classmethod
    def from_eigenpairs(
        cls,
        mean: torch.Tensor,
        components: torch.Tensor,
        eigenvalues: torch.Tensor,
        total: torch.Tensor,
        n_samples: int,
        image_shape: tuple[int, int, int] | None,
        dtype: torch.dtype,
    ) -> EigenFit:
        """The record, every tensor in the data's ``dtype``, signs fixed by :func:`peak_signs`.

        ``mean`` (N,), ``components`` (k, N) and ``eigenvalues`` (k,) may be of any float
        dtype; ``total`` () is the sum of all eigenvalues, trace(Xc Xcᵀ).
        """
        components = components.to(dtype).contiguous()
        return cls(
            mean=mean.to(dtype),
            components=components * peak_signs(components, dim=1),
            eigenvalues=eigenvalues.to(dtype),
            ratio=(eigenvalues / total).to(dtype),
            n_samples=n_samples,
            image_shape=image_shape,
        )

    @property
    def n_components(self) -> int:
        """k."""
        return self.components.shape[0]

    @property
    def n_features(self) -> int:
        """N."""
        return self.mean.shape[0]

    @property
    def dtype(self) -> torch.dtype:
        """The dtype of every tensor of the record."""
        return self.mean.dtype


def gram(xc: torch.Tensor, panels: int = 4) -> torch.Tensor:
    """Xc Xcᵀ (P, P) of (P, N) rows from its upper block triangle, mirrored: a syrk-like product.

    torch has no syrk; computing only the row panels' blocks right of the diagonal does
    (panels + 1) / (2 panels) of the GEMM's 2·N·P² flops (10/16 for 4 panels) in large GEMMs,
    and the result is exactly symmetric, as eigh wants. Small P: one GEMM.
    """
    n_views = xc.shape[0]
    if n_views < 512:
        return xc @ xc.T
    edges = [n_views * i // panels for i in range(panels + 1)]
    out = xc.new_empty(n_views, n_views)
    for lo, hi in itertools.pairwise(edges):
        block = xc[lo:hi] @ xc[lo:].T  # (hi - lo, P - lo)
        out[lo:hi, lo:] = block
        out[hi:, lo:hi] = block[:, hi - lo :].T
    return out


def peak_signs(vectors: torch.Tensor, dim: int) -> torch.Tensor:
    """±1 per vector making its entry of largest magnitude positive (scikit-learn's ``svd_flip``).

    The one sign rule of the package: linear components are the rows of a (k, N) matrix
    (``dim=1``); kernel components are fixed by their training coordinates, the columns
    of a (P, k) matrix (``dim=0``).

    Args:
        vectors: a 2-D float tensor whose slices along ``dim`` are the vectors.
        dim: the dimension along which each vector runs.

    Returns:
        The signs, of ``vectors``' dtype, with ``dim`` kept as size 1: (k, 1) or (1, k).
    """
    peak = vectors.gather(dim, vectors.abs().argmax(dim=dim, keepdim=True))
    return torch.where(peak < 0, -1.0, 1.0).to(vectors.dtype)


def rank_tolerance(
    largest: float, uncentred: float, n_views: int, n_features: int, dtype: torch.dtype
) -> float:
    """Eigenvalues of a centred scatter or kernel matrix at or below this are rounding noise.

    Two sources, in the data's ``dtype`` whatever precision the eigensolver ran in: the
    Gram/scatter product, whose length-n dot products round to ~√n·eps relative to the
    largest eigenvalue ``largest``; and the centring, which leaves each entry of X − μ off
    by ~eps·|x|, noise of energy up to eps²·‖X‖² (``uncentred`` = ‖X‖², before centring;
    0 for a kernel matrix, centred in float64). The second alone is the largest eigenvalue
    of identical views whose mean does not come out exact, which a bound relative to
    ``largest`` cannot catch.
    """
    root, eps = math.sqrt(max(n_views, n_features)), torch.finfo(dtype).eps
    return max(largest * root * eps, uncentred * root * eps * eps)


def numerical_rank(
    eigvals: torch.Tensor, n_views: int, n_features: int, dtype: torch.dtype, uncentred: float = 0.0
) -> int:
    """How many of the descending (t,) ``eigvals`` lie above :func:`rank_tolerance`.

    Zero and negative eigenvalues never count, so the kept ones may be divided by √λ.
    """
    largest = float(eigvals[0])
    if largest <= 0:
        return 0
    tol = rank_tolerance(largest, uncentred, n_views, n_features, dtype)
    return int((eigvals > tol).sum())


def choose_k(
    n_components: int | float,
    eigvals: torch.Tensor,
    total: torch.Tensor,
    rank: int,
    *,
    empty: str,
    bound: str,
) -> int:
    """k from (t,) descending ``eigvals`` of which the leading ``rank`` are above the tolerance.

    An int ``n_components`` is k; a fraction in (0, 1) gives the smallest k with
    Σ_{i<=k} λ_i / ``total`` >= fraction, at most ``rank``.

    Raises:
        ValueError: ``rank`` is 0 (message ``empty``), or an int ``n_components`` exceeds it
            ("n_components=k exceeds {bound}").
    """
    if rank == 0:
        raise ValueError(empty)
    if isinstance(n_components, int):
        if n_components > rank:
            raise ValueError(f"n_components={n_components} exceeds {bound}")
        return n_components
    cumulative = torch.cumsum(eigvals[:rank], 0) / total
    return min(int((cumulative < n_components).sum()) + 1, rank)


def centred_k(
    n_components: int | float,
    eigvals: torch.Tensor,
    total: torch.Tensor,
    mean: torch.Tensor,
    n_views: int,
    dtype: torch.dtype,
    name: str,
) -> int:
    """k for P centred views: :func:`numerical_rank`, then :func:`choose_k`.

    ``eigvals`` (t,) are the leading eigenvalues of the centred scatter, descending;
    ``total`` () its trace; ``mean`` (N,) the mean view, for ‖X‖² = ``total`` + P‖μ‖²
    (the centring's rounding); ``name`` names the views in the messages ("X").
    """
    uncentred = float(total) + n_views * float(mean.double().square().sum())
    rank = numerical_rank(eigvals, n_views, mean.numel(), dtype, uncentred)
    return choose_k(
        n_components,
        eigvals,
        total,
        rank,
        empty=f"{name} has rank 0 after centring: all {n_views} views are identical",
        bound=f"the rank of {name} ({rank}: {n_views} views, centred)",
    )


def leading_eigenpairs(
    scatter: torch.Tensor,
    n_components: int | float,
    mean: torch.Tensor,
    n_views: int,
    dtype: torch.dtype,
    name: str,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The k leading eigenpairs of a centred float64 Gram (P, P) or scatter (N, N) matrix.

    Returns:
        Eigenvalues (k,), eigenvectors (P or N, k) as columns, and the trace (), all float64.

    Raises:
        ValueError: as :func:`centred_k`.
    """
    top = n_components if isinstance(n_components, int) else None
    eigvals, basis = eigh_descending(scatter, top)
    total = scatter.diagonal().sum()
    k = centred_k(n_components, eigvals, total, mean, n_views, dtype, name)
    return eigvals[:k], basis[:, :k], total


def sketch_matrix(
    n_components: int | float, oversample: int, n_views: int, n_features: int, seed: int, device: torch.device
) -> torch.Tensor:
    """Ω (P, l) float64 of the range finder, l = k + ``oversample`` (capped by P and N).

    Drawn on the CPU from ``seed`` and moved, so its rows, indexed by the global view
    number, are the same on every device and in every process.
    """
    k_max = n_components if isinstance(n_components, int) else min(n_views, n_features)
    width = min(k_max + oversample, n_views, n_features)
    gen = torch.Generator(device="cpu").manual_seed(seed)
    return torch.randn(n_views, width, generator=gen, dtype=torch.float64).to(device)


def randomized_passes(
    stream: Iterable[torch.Tensor],
    mean64: torch.Tensor,
    omega: torch.Tensor,
    n_iter: int,
    all_reduce: Callable[[torch.Tensor], torch.Tensor],
    row_offset: int,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The range finder's passes over (this process's) blocks (Halko et al. 2011, Alg. 4.4).

    Args:
        stream: the blocks, (P_b, N) each; iterated 2 + ``n_iter`` times.
        mean64: (N,) float64 mean of all views (of all processes).
        omega: (P, l) float64 test matrix, rows indexed by the global view number.
        n_iter: power iterations.
        all_reduce: sums a tensor over processes (identity in one process).
        row_offset: global number of this process's first view.

    Returns:
        Q (N, l) orthonormal, Z = Xc Q (P, l) (all processes' rows, summed in), and
        trace(Xc Xcᵀ), all float64.
    """
    y = torch.zeros(mean64.numel(), omega.shape[1], dtype=torch.float64, device=mean64.device)
    start = row_offset
    for b in stream:
        stop = start + b.shape[0]
        y += ((b - mean64.to(b.dtype)).T @ omega[start:stop].to(b.dtype)).double()
        start = stop
    y = all_reduce(y)
    for _ in range(n_iter):
        q = torch.linalg.qr(y).Q
        y = torch.zeros_like(y)
        for b in stream:
            bc = b - mean64.to(b.dtype)
            y += (bc.T @ (bc @ q.to(b.dtype))).double()
        y = all_reduce(y)
    q = torch.linalg.qr(y).Q
    z = torch.zeros(omega.shape, dtype=torch.float64, device=mean64.device)
    total = torch.zeros((), dtype=torch.float64, device=mean64.device)
    start = row_offset
    for b in stream:
        bc = b - mean64.to(b.dtype)
        stop = start + b.shape[0]
        z[start:stop] = (bc @ q.to(b.dtype)).double()
        total += bc.double().square().sum()
        start = stop
    return q, all_reduce(z), all_reduce(total)


def sketch_components(
    q: torch.Tensor,
    z: torch.Tensor,
    total: torch.Tensor,
    n_components: int | float,
    mean64: torch.Tensor,
    n_views: int,
    dtype: torch.dtype,
    name: str,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Components from the sketch Z = Xc Q (P, l), Q (N, l) orthonormal: Z = U S Wᵀ, Xc ≈ U S (Q W)ᵀ.

    Returns:
        Eigenvalues (k,) and components (k, N), float64, signs not yet fixed.

    Raises:
        ValueError: as :func:`centred_k`, or an energy fraction the l directions of the
            sketch do not reach.
    """
    _, s, wt = torch.linalg.svd(z, full_matrices=False)
    eigvals = s.square()
    k = centred_k(n_components, eigvals, total, mean64, n_views, dtype, name)
    if not isinstance(n_components, int) and float(eigvals[:k].sum() / total) < n_components:
        raise ValueError(
            f"n_components={n_components} (energy fraction) needs more than the {eigvals.numel()} "
            "directions of the randomized sketch: raise oversample or use solver='exact'"
        )
    return eigvals[:k], wt[:k] @ q.T
