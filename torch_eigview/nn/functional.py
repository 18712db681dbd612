"""Functional pieces of the frozen layers."""

from __future__ import annotations

import torch

__all__ = ["unit_rows"]


def unit_rows(x: torch.Tensor) -> torch.Tensor:
    """(B, ...) views → (B, N) vectors of unit L2 norm (Murase and Nayar's brightness
    normalization); an all-zero view stays zero. Export-friendly: no data-dependent branch.

    Each row is first divided by its largest magnitude, as LAPACK's ``nrm2`` scales: the
    squares of a view times 1e20 overflow float32 and those of a view times 1e-30
    underflow, the ratios never do, so a view and any positive multiple of it give the
    same unit vector (to rounding).

    Example:
        >>> x = torch.rand(2, 1, 4, 4)
        >>> bool(torch.allclose(unit_rows(x * 1e30), unit_rows(x)) and torch.allclose(unit_rows(x * 1e-30), unit_rows(x)))
        True
    """
    v = x.flatten(1)
    tiny = torch.finfo(v.dtype).tiny
    w = v / v.abs().amax(dim=1, keepdim=True).clamp_min(tiny)
    return w / w.norm(dim=1, keepdim=True).clamp_min(tiny)
