"""Functional pieces of the frozen layers."""

from __future__ import annotations

import math

import torch

__all__ = ["unit_rows"]


def _traced() -> bool:
    """Under torch.compile, torch.export (the ONNX exporter) or TorchScript: no data-dependent
    branch may be taken there."""
    return bool(torch.compiler.is_compiling() or torch.jit.is_tracing() or torch.jit.is_scripting())


def unit_rows(x: torch.Tensor) -> torch.Tensor:
    """(B, ...) views → (B, N) vectors of unit L2 norm (Murase and Nayar's brightness
    normalization); an all-zero view stays zero.

    A view and any positive multiple of it give the same unit vector (to rounding): the
    squares of a view times 1e20 overflow float32 and those of a view times 1e-30
    underflow, so such rows are first divided by their largest magnitude, as LAPACK's
    ``nrm2`` scales. Eagerly on the CPU the plain norm is taken first and kept where it is
    exact (finite, and large enough that no square that matters underflowed: at least
    ``sqrt(tiny) / eps · sqrt(N)``), one pass fewer for ordinary views; traced (torch.compile,
    ONNX export), and on other devices (no host sync), every row is scaled, with no
    data-dependent branch.

    Example:
        >>> x = torch.rand(2, 1, 4, 4)
        >>> bool(torch.allclose(unit_rows(x * 1e30), unit_rows(x)) and torch.allclose(unit_rows(x * 1e-30), unit_rows(x)))
        True
    """
    v = x.flatten(1)
    info = torch.finfo(v.dtype)
    if v.device.type == "cpu" and not _traced():
        norm = torch.linalg.vector_norm(v, dim=1, keepdim=True)
        # Below this norm the largest entry may be so small that squares within eps of its
        # own underflowed (m >= norm / sqrt(N) >= sqrt(tiny) / eps keeps them); a norm of 0
        # may be all squares underflowing, so an all-zero view takes the scaled path too.
        floor = math.sqrt(info.tiny) / info.eps * math.sqrt(max(v.shape[1], 1))
        exact = torch.isfinite(norm) & (norm >= floor)
        if bool(exact.all()):
            return v / norm.clamp_min(info.tiny)
    w = v / v.abs().amax(dim=1, keepdim=True).clamp_min(info.tiny)
    return w / w.norm(dim=1, keepdim=True).clamp_min(info.tiny)
