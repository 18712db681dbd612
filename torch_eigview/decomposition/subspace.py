"""The k leading eigenpairs of a large centred scatter Xcᵀ Xc by block subspace iteration.

For a few leading eigenpairs of many large views (P and N both in the thousands, as the
full circle's gallery of 7,200 views × 16,384 values), forming the P×P Gram matrix costs
about P²·N multiply-adds while only k ≪ P eigenpairs are wanted. Subspace iteration with
Rayleigh–Ritz (Saad, *Numerical Methods for Large Eigenvalue Problems*, 2011, Ch. 5)
touches the data only through products with a block of l = k + oversample vectors
(:data:`SUBSPACE_OVERSAMPLE` by default): each iteration is W = Xc V (P, l) and
Y = Xcᵀ W (N, l), about 4·P·N·l flops, so it wins when a few iterations cost less than
the Gram matrix.

Each iteration takes the SVD of the small W = U S Zᵀ: the Ritz pairs are s_i² (the
eigenvalues) and v_i = V z_i (the components), and Y z_i = s_i Xcᵀ u_i gives every pair's
residual ‖Xcᵀ u_i − s_i v_i‖ without another product. The iteration stops when the k
leading residuals are at most ``tol`` · s_1 (converged, not a fixed number of passes: the
result is the exact eigenspace to that tolerance), or gives up (returns None, and the
caller takes the exact path) after ``max_iter`` iterations, or earlier once the rate at
which its residuals fall shows that it will not converge within them. Its products run in the
data's dtype, the small problems in float64; with the default tolerance its float32
components lie about as close to a float64 reference as the float32 Gram path's (on the
COIL-20 full-circle gallery of 7,200 × 16,384 values, k = 15: largest principal angles of
2.1e-6 and 1.2e-6 rad, taken by the sine of the projection, not the arccosine, which
cannot resolve angles below about 3e-4 in float32).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

__all__ = [
    "SUBSPACE_OVERSAMPLE",
    "default_tolerance",
    "iteration_budget",
    "leading_by_subspace",
    "subspace_eigenpairs",
]

#: Extra vectors in the block beyond k by default (``oversample="auto"`` of
#: ``Eigenspace`` and ``StreamingEigenspace``). The leading k converge at the rate
#: λ_{l+1} / λ_k per iteration, so a wider block needs fewer iterations of more
#: arithmetic each. For a block of a few dozen vectors an iteration costs about what
#: reading the (P, N) views twice costs, whatever l (a product with so thin a block is
#: bound by the data it reads, not by its arithmetic), and in a stream each iteration is
#: a pass over the source: the iterations are what to save. On the COIL-20 full-circle
#: gallery (7,200 × 16,384 values, k = 15) the iteration converges in about 13 iterations
#: with 10 extra vectors, 9 with 20 and 7 with 35.
SUBSPACE_OVERSAMPLE = 35

#: Products = a function of the block V (N, l) giving ``(Xc V, Xcᵀ (Xc V))``.
Products = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]]


def iteration_budget(n_views: int, n_features: int, width: int) -> int:
    """Iterations (each about 4·P·N·l flops, l = ``width``) that cost half what the exact
    path's products do (about (10/16)·2·P²·N flops for the Gram matrix by panels when
    N > P, else 2·P·N² for the scatter), at least one. The iteration is stopped as soon as
    its rate shows it will not converge within them (from the third iteration), and the
    exact path takes over: a spectrum without a gap costs a few iterations (three to six in
    the tests and benchmarks) on top of the exact path, one that converges at most half of
    the exact path's products."""
    if n_features > n_views:
        exact = 1.25 * n_views * n_views * n_features
    else:
        exact = 2.0 * n_views * n_features * n_features
    return max(1, int(exact // (8 * n_views * n_features * width)))


#: :func:`default_tolerance` per dtype: the loosest that leaves the float32 components
#: about as close to a float64 reference as the float32 Gram path's own. On the COIL-20
#: full-circle gallery (float32, k = 15), against the float64 Gram path's components,
#: 1e-5 took 7 iterations and left them 1.4e-5 rad off, 1e-6 took 8 and 2.1e-6 rad (the
#: float32 Gram path: 1.2e-6 rad), 3e-7 took 9 and 5.3e-7 rad. In float64 a millionth of
#: that.
_TOLERANCE = {torch.float32: 1e-6, torch.float64: 1e-12}


def default_tolerance(dtype: torch.dtype) -> float:
    """Residual tolerance relative to s_1: 1e-6 in float32, 1e-12 in float64 (within a
    factor of two of the Gram path's own distance from a float64 reference), 1e-3 for a
    lower precision."""
    return _TOLERANCE.get(dtype, 1e-3)


def subspace_eigenpairs(
    products: Products,
    n_features: int,
    k: int,
    dtype: torch.dtype,
    device: torch.device,
    *,
    max_iter: int,
    oversample: int = SUBSPACE_OVERSAMPLE,
    tol: float | None = None,
    seed: int = 0,
) -> tuple[torch.Tensor, torch.Tensor, int] | None:
    """The k leading eigenpairs of Xcᵀ Xc, Xc reached only through ``products``.

    Args:
        products: V (N, l) in ``dtype`` → ``(W, Y)``, W = Xc V (P, l) and Y = Xcᵀ W (N, l).
        n_features: N; ``k``: the eigenpairs wanted, with k + ``oversample`` <= N and <= P.
        dtype, device: of the products.
        max_iter: the most iterations before giving up.
        oversample: l − k.
        tol: residual tolerance relative to s_1 (default :func:`default_tolerance`).
        seed: seed of the random start block (drawn in float64 on the CPU: the same start
            on every device).

    Returns:
        ``(eigenvalues, components, iterations)``: (k,) float64 descending, (k, N) float64
        orthonormal rows, and the iterations taken; None when ``max_iter`` iterations did
        not converge, or when, from the third iteration, the rate at which the residuals
        fall would not reach the tolerance within them.
    """
    tol = default_tolerance(dtype) if tol is None else tol
    width = k + oversample
    gen = torch.Generator(device="cpu").manual_seed(seed)
    start = torch.randn(n_features, width, generator=gen, dtype=torch.float64)
    v = torch.linalg.qr(start).Q.to(device=device, dtype=dtype)
    worst: list[float] = []
    for it in range(1, max_iter + 1):
        w, y = products(v)
        _, s, zt = torch.linalg.svd(w.double(), full_matrices=False)
        z = zt.T[:, :k]
        ritz = v.double() @ z  # (N, k) orthonormal: V is, and Z's columns are
        # Y z_i = Xcᵀ W z_i = s_i Xcᵀ u_i: the residual times s_i, no division by a zero s_i.
        scaled = (y.double() @ z - ritz * s[:k].square()).norm(dim=0)
        bound = tol * s[0] * s[:k]
        if bool((scaled <= bound).all()):
            return s[:k].square(), ritz.T.contiguous(), it
        worst.append(float((scaled / torch.where(bound > 0, bound, 1.0)).max()))
        if not _on_course(worst, it, max_iter):
            return None
        # span(Y) = Xcᵀ Xc span(V): the next block, orthonormal.
        v = torch.linalg.qr(y.double()).Q.to(dtype)
    return None


def _on_course(worst: list[float], it: int, max_iter: int) -> bool:
    """Whether the iteration, at the rate its worst residual (in units of the tolerance)
    fell over the last two iterations, reaches the tolerance within ``max_iter``: from the
    third iteration on, one that will not is stopped at once rather than at the budget."""
    if it < 3:
        return True
    if not (math.isfinite(worst[-1]) and math.isfinite(worst[-3])):
        return False  # an overflow: no rate to read
    rate = math.sqrt(worst[-1] / worst[-3])
    if not 0 < rate < 1:
        return False
    return it + math.log(worst[-1]) / -math.log(rate) <= max_iter


def leading_by_subspace(
    products: Products,
    k: int,
    n_views: int,
    n_features: int,
    dtype: torch.dtype,
    device: torch.device,
    oversample: int = SUBSPACE_OVERSAMPLE,
) -> tuple[torch.Tensor, torch.Tensor] | None:
    """:func:`subspace_eigenpairs` for P × N views with a block of up to k + ``oversample``
    vectors and :func:`iteration_budget`'s iterations: eigenvalues (k,) and components
    (k, N), float64, or None (no room for a vector beyond k, or no convergence)."""
    width = min(k + oversample, n_views, n_features)
    if width < k + 1:
        return None
    found = subspace_eigenpairs(
        products,
        n_features,
        k,
        dtype,
        device,
        max_iter=iteration_budget(n_views, n_features, width),
        oversample=width - k,
    )
    return None if found is None else found[:2]
