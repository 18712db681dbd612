"""Functional pieces of the frozen layers."""

from __future__ import annotations

import torch

__all__ = ["unit_rows"]


def unit_rows(x: torch.Tensor) -> torch.Tensor:
    """(B, ...) views → (B, N) vectors of unit L2 norm (Murase and Nayar's brightness
    normalization); an all-zero view stays zero. Export-friendly: no data-dependent branch."""
    v = x.flatten(1)
    return v / v.norm(dim=1, keepdim=True).clamp_min(torch.finfo(v.dtype).tiny)
