"""The float64 symmetric eigensolver every fit shares, and SciPy's BLAS threads.

:func:`eigh_descending` returns a matrix's eigenpairs by decreasing eigenvalue: the few
leading ones of a large matrix by Lanczos in torch (ARPACK, then LAPACK's subset
solver, where that does not converge), else all of them by ``torch.linalg.eigh``.
Re-exported by :mod:`torch_eigview.decomposition.linalg`.
"""

from __future__ import annotations

import contextlib

import torch

__all__ = ["LANCZOS_STEPS", "eigh_descending", "single_threaded_blas"]


_BLAS_CONTROLLER: list[object] = []  # a cached threadpoolctl.ThreadpoolController, when installed


def single_threaded_blas() -> contextlib.AbstractContextManager[object]:
    """SciPy's BLAS (OpenBLAS) limited to one thread, when threadpoolctl is installed.

    Torch's thread pool runs the GEMMs right before and after the eigensolver, and
    OpenBLAS keeps a pool of its own: with both sized to the cores, the two pools' workers
    spin for the same cores while the other pool's work runs. A moderate matrix (the
    caller's choice, n <= 2048) gains little from OpenBLAS threads, so it runs with one.
    """
    if not _BLAS_CONTROLLER:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - a dependency; kept optional for vendored installs
            _BLAS_CONTROLLER.append(None)
        else:
            _BLAS_CONTROLLER.append(ThreadpoolController())
    controller = _BLAS_CONTROLLER[0]
    if controller is None:
        return contextlib.nullcontext()
    limited: contextlib.AbstractContextManager[object] = controller.limit(  # type: ignore[attr-defined]
        limits=1, user_api="blas"
    )
    return limited


def eigh_descending(
    matrix: torch.Tensor, top: int | None = None, *, lanczos_steps: int | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Eigenpairs of a symmetric float64 (n, n) matrix by decreasing eigenvalue.

    For a few leading pairs of a large matrix on the CPU (``top`` given, n >= 256 and
    ``top`` <= n / 4, where computing all n pairs would be mostly waste): Lanczos with full
    reorthogonalization in torch (:func:`_leading_by_lanczos`) until every leading pair's
    residual is at the level of rounding. On COIL-20's Gram (n = 820, k = 15) that takes
    48 steps, 48 products with the matrix, and gives eigenvalues equal to LAPACK's to
    5e-16 of the largest; SciPy is not imported. Where it has not converged within
    ``lanczos_steps`` (a flat spectrum: white noise, a kernel near the identity) or cannot
    go on, ARPACK's implicitly restarted Lanczos (SciPy's ``eigsh``, ``tol=0``, a fixed
    pseudo-random start) and, where that does not converge or cannot start (a zero
    matrix), LAPACK's ``dsyevr`` (MRRR, backward stable) take over. Every route ends at
    the same pairs to rounding. Otherwise all pairs, by ``torch.linalg.eigh``. The rank
    (eigenvalues above a tolerance) is exact from the leading ``top``: when it is below
    ``top`` the remaining eigenvalues, smaller, are below it too.

    Args:
        matrix: (n, n) symmetric float64.
        top: the number of leading pairs wanted, or None for all.
        lanczos_steps: the most Lanczos steps before ARPACK takes over; None is
            :data:`LANCZOS_STEPS` (256). It decides which solver's rounding the pairs
            carry, not how close they are.

    Returns:
        Eigenvalues (t,) descending and eigenvectors (n, t) as columns: t = ``top`` for a
        large matrix, else all n (also when ``top`` is None).
    """
    n = matrix.shape[0]
    if top is not None and matrix.device.type == "cpu" and n >= 256 and top <= n // 4:
        steps = LANCZOS_STEPS if lanczos_steps is None else lanczos_steps
        found = _leading_by_lanczos(matrix, top, steps)
        if found is not None:
            return found
        return _leading_by_arpack(matrix, top)
    w, v = torch.linalg.eigh(matrix)
    return w.flip(0), v.flip(1)


#: The most Lanczos steps of :func:`eigh_descending` before ARPACK takes over. A step
#: costs a product with the matrix (2·n² flops) plus its full reorthogonalization against
#: the j earlier vectors (8·n·j flops), and the basis holds steps × n values: by step
#: 256 a step's reorthogonalization costs what its product does at n = 1,024 and more
#: below, and a spectrum that has not converged by then (COIL-20's Gram takes 48 steps)
#: is one ARPACK's restarts handle in bounded memory.
LANCZOS_STEPS = 256


def _leading_by_lanczos(
    matrix: torch.Tensor, top: int, max_steps: int
) -> tuple[torch.Tensor, torch.Tensor] | None:
    """The ``top`` largest eigenpairs of a symmetric (n, n) float64 matrix by Lanczos with
    full reorthogonalization, or None where they have not converged within ``max_steps``
    steps (or cannot: a zero matrix, an invariant subspace of fewer than ``top``
    dimensions).

    From a fixed pseudo-random start, each step multiplies one vector by the matrix and
    orthogonalizes it against every earlier one (twice: the basis stays orthonormal to
    rounding, so no spurious copies of converged pairs appear). From ``max(2 top + 1,
    48)`` steps on (ARPACK's ``ncv`` here), every 16 steps, the Ritz pairs of the
    tridiagonal matrix are the estimates; once every leading residual estimate is within
    ``max(1e-12, 8 n eps)`` of the largest Ritz value (rounding leaves about ``n eps`` of
    it), the residuals ``|A v - w v|`` are computed and must pass the same bound.
    """
    n = matrix.shape[0]
    if not bool(matrix.any()):
        return None
    limit = min(n, max_steps)
    tol = max(1e-12, 8 * n * torch.finfo(matrix.dtype).eps)
    gen = torch.Generator().manual_seed(0)
    start = torch.randn(n, generator=gen, dtype=matrix.dtype).to(matrix.device)
    basis = matrix.new_zeros(limit + 1, n)
    basis[0] = start / start.norm()
    alphas, betas = matrix.new_zeros(limit), matrix.new_zeros(limit)
    first = max(2 * top + 1, 48)
    for j in range(limit):
        w = matrix @ basis[j]
        alphas[j] = basis[j] @ w
        done = basis[: j + 1]
        for _ in range(2):
            w -= done.T @ (done @ w)
        betas[j] = w.norm()
        steps = j + 1
        # An invariant subspace (beta ~ 0): its Ritz pairs are exact, and there is no
        # further direction to find.
        scale = float(alphas[:steps].abs().amax())
        breakdown = not float(betas[j]) > torch.finfo(matrix.dtype).eps * max(scale, 1e-300)
        due = breakdown or steps == limit or (steps >= first and (steps - first) % 16 == 0)
        if due and steps >= top:
            found = _ritz_pairs(matrix, basis[:steps], alphas[:steps], betas[:steps], top, tol)
            if found is not None:
                return found
        if breakdown:
            return None
        basis[j + 1] = w / betas[j]
    return None


def _ritz_pairs(
    matrix: torch.Tensor, basis: torch.Tensor, alphas: torch.Tensor, betas: torch.Tensor, top: int, tol: float
) -> tuple[torch.Tensor, torch.Tensor] | None:
    """The ``top`` largest Ritz pairs of a Lanczos ``basis`` (m, n) whose tridiagonal has
    ``alphas`` and ``betas`` (m,), when converged (:func:`_leading_by_lanczos`)."""
    off = betas[:-1]
    tri = torch.diag(alphas) + torch.diag(off, 1) + torch.diag(off, -1)
    ritz, s = torch.linalg.eigh(tri)  # ascending
    w, s = ritz.flip(0)[:top], s.flip(1)[:, :top]
    scale = float(ritz.abs().amax())
    if not scale > 0 or float((betas[-1] * s[-1]).abs().amax()) > tol * scale:
        return None
    v = basis.T @ s
    if float((matrix @ v - v * w).norm(dim=0).amax()) > tol * scale:
        return None
    return w.contiguous(), v


def _leading_by_arpack(matrix: torch.Tensor, top: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``top`` leading eigenpairs by ARPACK, else LAPACK's subset ``dsyevr``."""
    import numpy as np
    from scipy.linalg import eigh  # scikit-image depends on SciPy
    from scipy.sparse.linalg import ArpackNoConvergence, eigsh

    n = matrix.shape[0]
    a = matrix.numpy()
    with single_threaded_blas() if n <= 2048 else contextlib.nullcontext():
        # Not the ones vector: it spans the null space of a centred Gram matrix.
        v0 = np.random.default_rng(0).standard_normal(n)
        found = None
        if a.any():  # ARPACK cannot start on a zero matrix (identical views)
            try:
                found = eigsh(a, k=top, which="LA", tol=0, v0=v0, ncv=min(n, max(2 * top + 1, 48)))
            except ArpackNoConvergence:
                pass
        w, v = found or eigh(a, subset_by_index=[n - top, n - 1], driver="evr", check_finite=False)
    order = np.argsort(w)[::-1].copy()
    return torch.from_numpy(w[order]), torch.from_numpy(np.ascontiguousarray(v[:, order]))
