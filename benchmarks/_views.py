"""Synthetic views for the benchmarks: any number of objects, views and pixels, no data set."""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["smooth_views"]


def smooth_views(obj: int, n_views: int = 41, channels: int = 1, size: int = 128) -> torch.Tensor:
    """(n_views, channels, size, size) float32 random smooth views of synthetic object ``obj``.

    A random low-resolution texture (seeded by ``obj``) is upsampled bicubically to
    ``size`` × (``size`` + ``n_views``) and view t is the window starting at column t: the
    object slides by one pixel per view, so consecutive views are correlated like a
    turntable sequence. Deterministic: the same call gives the same views.
    """
    gen = torch.Generator().manual_seed(1_000_003 * obj + 17)
    low = torch.rand(1, channels, 8, 8 + max(1, (8 * n_views) // size), generator=gen)
    wide = F.interpolate(low, size=(size, size + n_views), mode="bicubic", align_corners=False)[0]
    cols = torch.arange(size)[None, :] + torch.arange(n_views)[:, None]  # (T, size)
    return wide[:, :, cols].permute(2, 0, 1, 3).contiguous().clamp_(0, 1)
