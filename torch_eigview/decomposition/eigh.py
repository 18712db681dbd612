"""The float64 symmetric eigensolver every fit shares, and SciPy's BLAS threads.

:func:`eigh_descending` returns a matrix's eigenpairs by decreasing eigenvalue: the few
leading ones of a large matrix by subspace iteration in torch (ARPACK, then LAPACK's
subset solver, where that does not converge), else all of them by ``torch.linalg.eigh``.
Re-exported by :mod:`torch_eigview.decomposition.linalg`.
"""

from __future__ import annotations

import contextlib

import torch

__all__ = ["SUBSPACE_ITERATIONS", "eigh_descending", "single_threaded_blas"]


_BLAS_CONTROLLER: list[object] = []  # a cached threadpoolctl.ThreadpoolController, when installed


def single_threaded_blas() -> contextlib.AbstractContextManager[object]:
    """SciPy's BLAS (OpenBLAS) limited to one thread, when threadpoolctl is installed.

    Between torch's thread pool (busy right before and after, GEMMs) and OpenBLAS's own,
    two pools contend for the cores: on 2 cores the COIL-20 fit spends ~40 ms more in the
    eigh and the components product than with OpenBLAS on one thread (spinning workers).
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


def eigh_descending(matrix: torch.Tensor, top: int | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Eigenpairs of a symmetric float64 (n, n) matrix by decreasing eigenvalue.

    For a few leading pairs of a large matrix on the CPU: subspace iteration in torch
    (:func:`_leading_by_subspace`) until every leading pair's residual is at the level of
    rounding; on image data, whose spectrum decays, a dozen products with an (n, 48)
    block (COIL-20's Gram, n = 820, k = 15: 12 iterations, 0.03 s, eigenvalues equal to
    LAPACK's to 2e-15 of the largest), and SciPy is not imported (its first import cost a
    command about 0.2 s). Where it has not converged within its budget (a flat spectrum:
    white noise, a kernel near the identity), ARPACK's implicitly restarted Lanczos
    (SciPy's ``eigsh``, ``tol=0``, a fixed pseudo-random start) and, where that does not
    converge or cannot start (a zero matrix), LAPACK's ``dsyevr`` (MRRR, backward stable)
    take over. The rank (eigenvalues above a tolerance) is exact from the leading
    ``top``: when it is below ``top`` the remaining eigenvalues, smaller, are below it too.

    Returns:
        Eigenvalues (t,) descending and eigenvectors (n, t) as columns: t = ``top`` for a
        large matrix, else all n (also when ``top`` is None).
    """
    n = matrix.shape[0]
    if top is not None and matrix.device.type == "cpu" and n >= 256 and top <= n // 4:
        found = _leading_by_subspace(matrix, top)
        if found is not None:
            return found
        return _leading_by_arpack(matrix, top)
    w, v = torch.linalg.eigh(matrix)
    return w.flip(0), v.flip(1)


#: Subspace iterations before ARPACK takes over (COIL-20's Gram needs 12).
SUBSPACE_ITERATIONS = 40


def _leading_by_subspace(matrix: torch.Tensor, top: int) -> tuple[torch.Tensor, torch.Tensor] | None:
    """The ``top`` leading eigenpairs of a symmetric (n, n) float64 matrix by subspace
    iteration with Rayleigh–Ritz, or None where they have not converged within
    :data:`SUBSPACE_ITERATIONS` (or the matrix is zero).

    A block of ``max(2 top + 1, 48)`` columns (ARPACK's ``ncv`` here), from a fixed
    pseudo-random start, is multiplied by the matrix and orthonormalized; after each
    product the Ritz pairs of the block are the estimates, converged when every leading
    residual ``|A v - w v|`` is within ``max(1e-12, 8 n eps)`` of the largest eigenvalue
    (rounding leaves about ``n eps`` of it). Pair i converges as
    ``(lambda_{block+1} / lambda_i)^iterations``. For a positive semi-definite matrix (a
    Gram or scatter matrix); one whose block shows a negative eigenvalue beyond rounding
    gives None.
    """
    n = matrix.shape[0]
    if not bool(matrix.any()):
        return None
    block = min(n, max(2 * top + 1, 48))
    gen = torch.Generator().manual_seed(0)
    start = torch.randn(n, block, generator=gen, dtype=matrix.dtype).to(matrix.device)
    q = torch.linalg.qr(matrix @ start).Q
    tol = max(1e-12, 8 * n * torch.finfo(matrix.dtype).eps)
    for _ in range(SUBSPACE_ITERATIONS):
        z = matrix @ q
        h = q.T @ z
        ritz, s = torch.linalg.eigh((h + h.T) / 2)  # ascending
        scale = float(ritz.abs().amax())
        if float(ritz[0]) < -tol * scale:
            # Negative eigenvalues of some size: the iteration finds the largest in
            # magnitude, not the largest; ARPACK's "LA" does.
            return None
        w, s = ritz.flip(0)[:top], s.flip(1)[:, :top]
        v = q @ s
        if scale > 0 and float((z @ s - v * w).norm(dim=0).amax()) <= tol * scale:
            return w.contiguous(), v
        q = torch.linalg.qr(z).Q
    return None


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
