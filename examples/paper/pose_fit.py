"""Eq. 2 run backwards, step by step: a view's angle from its points' columns in two seeds.

``pose_pair_choice.py`` needs what :func:`torch_eigview.synthesis.view_angles` computes
inside (the chained points, how many there are, and the fitted angle) for each of
several seed pairs, from one pair of flows each. The package keeps those steps in
``torch_eigview.geometry.view_pose`` and ``torch_eigview.synthesis.view_pose``, outside
its public API, so they are written out here for trusted inputs (no argument checks);
``examples/tests/test_pose_pair_choice.py`` checks that they give the library's poses.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from torch_eigview import Correspondence

#: The fewest points a fit accepts (three unknowns; a few dozen make the robust scale sane).
MIN_POINTS = 32
#: Huber's constant in units of the residuals' robust scale, and the reweighting passes.
HUBER, PASSES = 2.0, 10


def wrap_degrees(angles: torch.Tensor) -> torch.Tensor:
    """Angles wrapped to (−180, 180]."""
    return 180 - torch.remainder(180 - angles, 360)


def column_weight(image: torch.Tensor) -> torch.Tensor:
    """(H·W,) the magnitude of the (C, H, W) ``image``'s horizontal derivative (central
    differences, the channels' mean; 0 in the first and last column): a flow cannot see a
    pixel move along a row that does not vary, so such pixels count little in the fit."""
    gx = torch.zeros_like(image)
    gx[:, :, 1:-1] = (image[:, :, 2:] / 2 - image[:, :, :-2] / 2).abs()  # halved first: no overflow
    return gx.mean(dim=0).reshape(-1)


def _sample(fields: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """(N, F, H, W) ``fields`` sampled bilinearly at (r + flow[:, 0], c + flow[:, 1]), edge
    values outside (pixel coordinates, pixel centres at integers)."""
    h, w = fields.shape[-2:]
    rows = torch.arange(h, dtype=flow.dtype, device=flow.device).view(h, 1)
    cols = torch.arange(w, dtype=flow.dtype, device=flow.device)
    gx = (flow[:, 1] + cols) * (2.0 / max(w - 1, 1)) - 1
    gy = (flow[:, 0] + rows) * (2.0 / max(h - 1, 1)) - 1
    grid = torch.stack([gx, gy], dim=-1)
    return F.grid_sample(fields, grid, mode="bilinear", padding_mode="border", align_corners=True)


def chain_columns(
    to_view: Correspondence, to_seed2: Correspondence, foreground: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The columns of seed-1 pixels in seed 1, seed 2 and the view, through the view.

    A seed-1 pixel of ``foreground`` (H, W) trusted by ``to_view`` (seed 1 → view, (N, H, W))
    is followed into the view, vertical motion included, and ``to_seed2`` (view → seed 2)
    is read there bilinearly; a point counts where all four neighbours are trusted and it
    lands inside the view. Returns ``(x1, x2, x3, use)``, each (N, H·W).
    """
    n, h, w = to_view.disparity_12.shape
    d = to_view.disparity_12
    yy, xx = torch.meshgrid(
        torch.arange(h, dtype=d.dtype, device=d.device),
        torch.arange(w, dtype=d.dtype, device=d.device),
        indexing="ij",
    )
    dy = to_view.vertical_12 if to_view.vertical_12 is not None else torch.zeros_like(d)
    x3, y3 = xx + d, yy + dy
    read = _sample(
        torch.stack([to_seed2.disparity_12, to_seed2.valid_12.to(d.dtype)], 1), torch.stack([dy, d], 1)
    )
    x2, trusted = x3 + read[:, 0], read[:, 1] > 0.999
    # A point that lands outside the view has no match there (border padding would invent one).
    inside = (x3 >= 0) & (x3 <= w - 1) & (y3 >= 0) & (y3 <= h - 1)
    use = foreground.to(d.device) & to_view.valid_12 & trusted & inside
    return xx.expand_as(x3).reshape(n, -1), x2.reshape(n, -1), x3.reshape(n, -1), use.reshape(n, -1)


def fit_view_angle(
    x1: torch.Tensor,
    x2: torch.Tensor,
    x3: torch.Tensor,
    use: torch.Tensor,
    alpha: float,
    weight: torch.Tensor,
) -> torch.Tensor:
    """(N,) angle of each view in degrees from seed 1: ``x3 = a·x1 + b·x2 + e`` fitted by
    reweighted least squares (Huber weights on the median absolute residual's scale, times
    the prior ``weight`` (P,)), then ``atan2(b sin α, a + b cos α)``; NaN for a view with
    fewer than :data:`MIN_POINTS` points or with x1 and x2 nearly proportional."""
    al = math.radians(alpha)
    c1, c2, c3 = (v.to(torch.float64) for v in (x1, x2, x3))
    use = use & c1.isfinite() & c2.isfinite() & c3.isfinite()
    prior = weight.to(torch.float64).expand(use.shape)
    use = use & (prior > 0)
    # Scaled to at most 1 per view: the sums below neither overflow nor underflow.
    prior = prior / prior.amax(dim=1, keepdim=True).clamp_min(1e-300)
    c1, c2, c3 = (torch.where(use, v, 0.0) for v in (c1, c2, c3))
    n = use.shape[0]
    if use.shape[1] < MIN_POINTS:
        return torch.full((n,), math.nan, dtype=torch.float64)
    ok = use.sum(dim=1) >= MIN_POINTS
    base = torch.where(use, prior, 0.0)
    w = base
    a = b = c1.new_zeros(n)
    for _ in range(PASSES):
        total = w.sum(dim=1, keepdim=True).clamp_min(1e-300)
        d1, d2, d3 = ((v - (w * v).sum(dim=1, keepdim=True) / total) * use for v in (c1, c2, c3))
        s11, s22, s12 = ((w * u * v).sum(dim=1) for u, v in ((d1, d1), (d2, d2), (d1, d2)))
        s13, s23 = ((w * u * d3).sum(dim=1) for u in (d1, d2))
        det = s11 * s22 - s12 * s12
        # 1 − ρ² of x1 and x2: near 0 they are proportional and (a, b) undetermined.
        ok = ok & (det > 1e-9 * s11 * s22) & (s11 > 0) & (s22 > 0)
        safe = torch.where(ok, det, 1.0)
        a, b = (s22 * s13 - s12 * s23) / safe, (s11 * s23 - s12 * s13) / safe
        resid = (d3 - a[:, None] * d1 - b[:, None] * d2).abs()
        scale = 1.4826 * torch.where(use, resid, math.nan).nanmedian(dim=1).values.nan_to_num(1.0).clamp_min(
            1e-6
        )
        w = base * (HUBER * scale[:, None] / resid.clamp_min(1e-12)).clamp(max=1.0)
    theta = torch.rad2deg(torch.atan2(b * math.sin(al), a + b * math.cos(al)))
    return torch.where(ok, theta, math.nan)
