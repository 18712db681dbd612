"""Seed images and warp maps shared by the SparseViewOperator tests."""

from __future__ import annotations

import math

import torch

from torch_eigview.geometry.correspondence import correspondence_from_disparity
from torch_eigview.warp.maps import WarpMaps
from torch_eigview.warp.novel_view import NovelViewWarp

# G·C and kornia round differently (kornia goes pixel → normalized → pixel coordinates).
TOL = {torch.float32: 1e-5, torch.float64: 1e-12}
H, W = 12, 16
ALPHA = 10.0
# Extrapolation on both sides of [0, alpha], the seed angles themselves, and in between.
THETAS = [-12.0, -4.0, 0.0, 3.5, 10.0, 16.0, 25.0]


def generator(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def smooth_disparity(gen: torch.Generator, amplitude: float, dtype: torch.dtype) -> torch.Tensor:
    """(H, W) smooth random disparity, zero at the left and right borders."""
    y = torch.arange(H, dtype=torch.float64)[:, None]
    x = torch.arange(W, dtype=torch.float64)[None, :]
    phase, freq = torch.rand(2, generator=gen, dtype=torch.float64)
    bump = torch.sin(math.pi * x / (W - 1)) * (1 + 0.5 * torch.cos(y * (0.2 + 0.5 * freq) + 6 * phase))
    return (amplitude * bump).to(dtype)


def setup(
    dtype: torch.dtype, channels: int, n_sources: int, amplitude: float = 2.5, seed: int = 0
) -> tuple[torch.Tensor, WarpMaps]:
    gen = generator(seed)
    images = torch.rand(n_sources, channels, H, W, generator=gen, dtype=torch.float64).to(dtype)
    d12 = smooth_disparity(gen, amplitude, dtype)
    # An approximate reverse map: the consistency check then also marks pixels invalid,
    # which exercises the warp's hole filling and one-view regions.
    corr = correspondence_from_disparity(d12, -d12)
    maps = NovelViewWarp(ALPHA).maps(corr, THETAS, n_sources=n_sources)
    return images, maps


def assert_close(actual: torch.Tensor, expected: torch.Tensor, dtype: torch.dtype) -> None:
    assert actual.dtype == expected.dtype == dtype
    assert actual.shape == expected.shape
    diff = float((actual - expected).abs().max())
    assert diff <= TOL[dtype], f"max abs diff {diff:.3g} > {TOL[dtype]:.0e}"


def maps_2d(dtype: torch.dtype, n_sources: int, seed: int = 1) -> WarpMaps:
    """Smooth 2D target→source maps (a perspective-like warp), partly outside the image."""
    gen = generator(seed)
    t = len(THETAS)
    yy = torch.arange(H, dtype=torch.float64).view(H, 1).expand(H, W)
    xx = torch.arange(W, dtype=torch.float64).view(1, W).expand(H, W)
    src_x, src_y = [], []
    for _ in range(n_sources * t):
        p = torch.rand(4, generator=gen, dtype=torch.float64)
        src_x.append(xx * (0.9 + 0.2 * p[0]) + 2 * torch.sin(yy / 3 + 6 * p[1]) - 0.7)
        src_y.append(yy * (0.95 + 0.1 * p[2]) + 1.5 * torch.cos(xx / 4 + 6 * p[3]) + 0.3)
    shape = (n_sources, 1, t, H, W)
    weight = torch.rand(shape, generator=gen, dtype=torch.float64)
    weight = weight / weight.sum(0, keepdim=True)
    weight[..., :2, :3] = 0.0  # some target pixels take nothing
    sx = torch.stack(src_x).view(shape)
    sx[weight == 0] = 1e6  # ignored where the weight is zero
    return WarpMaps(
        sx.to(dtype),
        weight.to(dtype),
        weight > 0,
        torch.tensor(THETAS),
        torch.stack(src_y).view(shape).to(dtype),
    )
