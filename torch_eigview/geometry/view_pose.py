"""A view's angle between two seed views, from Eq. 2 over three-view correspondences.

Eq. 2 ties a point's column in a view at ``theta`` to its columns in the seed views at
0 and ``alpha`` (orthographic camera rotating about the vertical axis, whatever the
camera's elevation)::

    x3 = a·x1 + b·x2 + e,   a = sin(alpha − theta) / sin(alpha),   b = sin(theta) / sin(alpha),

with ``e = c (1 − a − b)`` for the axis column c. Given the three columns of many points,
(a, b, e) is a linear least-squares fit, and ``theta = atan2(b sin(alpha), a + b cos(alpha))``
(``a + b cos(alpha) = cos(theta)``, ``b sin(alpha) = sin(theta)``). No depth and no axis
column are needed: Eq. 2 has them eliminated. This is the pose of a test view by
geometry rather than by appearance (the eigenspace's nearest gallery view), the paper's
"future work": :func:`chain_columns` follows seed-1 pixels through two correspondences,
seed 1 → view and view → seed 2, and :func:`fit_view_angle` fits θ to the three columns;
:func:`torch_eigview.synthesis.view_angles` measures the correspondences with the
synthesis's flow.
"""

from __future__ import annotations

import math

import torch

from torch_eigview.check import check_alpha, check_float_tensor, check_ndim
from torch_eigview.geometry.correspondence import Correspondence, check_correspondence
from torch_eigview.geometry.tvl1 import warp_by_flow

__all__ = ["MIN_POINTS", "chain_columns", "fit_view_angle"]

#: The fewest points a fit accepts (three unknowns; a few dozen make the robust scale sane).
MIN_POINTS = 32

#: Huber's constant in units of the residuals' robust scale, and the reweighting passes.
_HUBER, _PASSES = 2.0, 10


def fit_view_angle(
    x1: torch.Tensor,
    x2: torch.Tensor,
    x3: torch.Tensor,
    use: torch.Tensor,
    alpha: float,
    weight: torch.Tensor | None = None,
) -> torch.Tensor:
    """The angle θ of each view from the columns of its points in both seeds and in it.

    Fits ``x3 = a·x1 + b·x2 + e`` per view by iteratively reweighted least squares (Huber
    weights, the scale from the median absolute residual), so mismatched points count
    little, and returns ``atan2(b sin α, a + b cos α)``. The columns are centred on their
    weighted means first (``e`` drops out), so the fit and its degeneracy test do not
    depend on where in the image the points lie.

    The three views must share one image scale up to a factor on x3: a view scaled on its
    own (an image normalized to its box) keeps Eq. 2, but a ratio r between the seeds'
    scales reads as b / r (at α = 45°, θ = 22.5°, r = 1.05 moves θ by about −0.6°).

    Args:
        x1, x2, x3: (N, P) columns of P points in seed 1 (at 0), seed 2 (at ``alpha``) and
            the view, per view n.
        use: (N, P) bool, the points to fit (non-finite columns are left out).
        alpha: the angle of seed 2 in degrees (not a multiple of 180).
        weight: optional (N, P) or (P,) non-negative prior weights of the points (how well
            their columns are measured), multiplying the Huber weights; a point of weight
            0 is left out.

    Returns:
        (N,) float64 angles in degrees from seed 1, in [−180, 180]; NaN for a view with
        fewer than :data:`MIN_POINTS` points, or whose points' x1 and x2 are (nearly)
        proportional, which leaves a and b undetermined.

    Raises:
        TypeError / ValueError: tensors of other shapes or kinds, or a bad ``alpha``.

    Example:
        >>> x1 = torch.tensor([[10.0, 40.0, 70.0, 20.0] * 10], dtype=torch.float64)
        >>> x2 = torch.tensor([[30.0, 35.0, 60.0, 50.0] * 10], dtype=torch.float64)
        >>> a, b = math.sin(math.radians(20)) / math.sin(math.radians(30)), math.sin(math.radians(10)) / math.sin(math.radians(30))
        >>> x3 = a * x1 + b * x2 + 5.0
        >>> round(float(fit_view_angle(x1, x2, x3, torch.ones_like(x1, dtype=torch.bool), 30.0)[0]), 6)
        10.0
    """
    al = math.radians(check_alpha(alpha))
    cols = []
    for v, name in ((x1, "x1"), (x2, "x2"), (x3, "x3")):
        cols.append(check_float_tensor(v, name))
        check_ndim(v, name, (2,), "(N, P)")
    if not isinstance(use, torch.Tensor) or use.dtype != torch.bool:
        raise TypeError(f"use must be a bool tensor, got {getattr(use, 'dtype', type(use).__name__)}")
    shapes = {tuple(v.shape) for v in (*cols, use)}
    if len(shapes) != 1:
        raise ValueError(f"x1, x2, x3 and use must have one shape (N, P), got shapes {sorted(shapes)}")
    prior = None if weight is None else _check_weight(weight, use.shape)
    # A small fit: float64 on the CPU where the device has no float64 (MPS).
    device = torch.device("cpu") if use.device.type == "mps" else use.device
    c1, c2, c3 = (v.to(device, torch.float64) for v in cols)
    use = use.to(device) & c1.isfinite() & c2.isfinite() & c3.isfinite()
    if prior is not None:
        prior = prior.to(device, torch.float64).expand(use.shape)
        use = use & (prior > 0)
        # Scaled to at most 1 per view: the sums below neither overflow nor underflow.
        prior = prior / prior.amax(dim=1, keepdim=True).clamp_min(1e-300)
    c1, c2, c3 = (torch.where(use, v, 0.0) for v in (c1, c2, c3))
    n = use.shape[0]
    if use.shape[1] < MIN_POINTS:
        return torch.full((n,), math.nan, dtype=torch.float64, device=device)
    ok = use.sum(dim=1) >= MIN_POINTS
    base = use.double() if prior is None else torch.where(use, prior, 0.0)
    weight = base
    a = b = c1.new_zeros(n)
    for _ in range(_PASSES):
        total = weight.sum(dim=1, keepdim=True).clamp_min(1e-300)
        d1, d2, d3 = ((v - (weight * v).sum(dim=1, keepdim=True) / total) * use for v in (c1, c2, c3))
        s11, s22, s12 = ((weight * u * v).sum(dim=1) for u, v in ((d1, d1), (d2, d2), (d1, d2)))
        s13, s23 = ((weight * u * d3).sum(dim=1) for u in (d1, d2))
        det = s11 * s22 - s12 * s12
        # 1 − ρ² of x1 and x2: near 0 they are proportional and (a, b) undetermined. NaN,
        # never a guess.
        ok = ok & (det > 1e-9 * s11 * s22) & (s11 > 0) & (s22 > 0)
        safe = torch.where(ok, det, 1.0)
        a, b = (s22 * s13 - s12 * s23) / safe, (s11 * s23 - s12 * s13) / safe
        resid = (d3 - a[:, None] * d1 - b[:, None] * d2).abs()
        scale = 1.4826 * torch.where(use, resid, math.nan).nanmedian(dim=1).values.nan_to_num(1.0).clamp_min(
            1e-6
        )
        weight = base * (_HUBER * scale[:, None] / resid.clamp_min(1e-12)).clamp(max=1.0)
    theta = torch.rad2deg(torch.atan2(b * math.sin(al), a + b * math.cos(al)))
    return torch.where(ok, theta, math.nan)


def _check_weight(weight: object, shape: torch.Size) -> torch.Tensor:
    """``weight`` of :func:`fit_view_angle`: a finite non-negative float tensor of shape
    (N, P) or (P,)."""
    w = check_float_tensor(weight, "weight")
    if tuple(w.shape) not in (tuple(shape), tuple(shape[1:])):
        raise ValueError(f"weight must have shape {tuple(shape)} or ({shape[1]},), got {tuple(w.shape)}")
    if not bool(torch.isfinite(w).all()) or bool((w < 0).any()):
        raise ValueError("weight must be finite and non-negative")
    return w


def chain_columns(
    to_view: Correspondence, to_seed2: Correspondence, foreground: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The columns of seed-1 pixels in seed 1, seed 2 and the view, through the view.

    A seed-1 pixel trusted by ``to_view`` is followed into the view (its vertical motion
    included, where the correspondence has one), and ``to_seed2`` is read there, bilinearly
    (its validity too: a point counts where all four neighbours are trusted, and only if
    it lands inside the view).

    Args:
        to_view: (N, H, W) correspondences seed 1 → view n.
        to_seed2: (N, H, W) correspondences view n → seed 2.
        foreground: (H, W) or (N, H, W) bool, the seed-1 pixels to follow (the object).

    Returns:
        ``(x1, x2, x3, use)``, each (N, H·W): the columns in seed 1, seed 2 and the view,
        and the points that passed, :func:`fit_view_angle`'s arguments.

    Raises:
        TypeError / ValueError: correspondences of other kinds or shapes, a bad mask.
    """
    to_view, to_seed2 = check_correspondence(to_view, "to_view"), check_correspondence(to_seed2, "to_seed2")
    if to_view.shape != to_seed2.shape:
        raise ValueError(
            f"to_view and to_seed2 must have one shape, got {to_view.shape} and {to_seed2.shape}"
        )
    n, h, w = to_view.shape
    if not isinstance(foreground, torch.Tensor) or foreground.dtype != torch.bool:
        raise TypeError(
            f"foreground must be a bool tensor, got {getattr(foreground, 'dtype', type(foreground).__name__)}"
        )
    if foreground.shape not in ((h, w), (n, h, w)):
        raise ValueError(
            f"foreground must have shape ({h}, {w}) or ({n}, {h}, {w}), got {tuple(foreground.shape)}"
        )
    d = to_view.disparity_12
    yy, xx = torch.meshgrid(
        torch.arange(h, dtype=d.dtype, device=d.device),
        torch.arange(w, dtype=d.dtype, device=d.device),
        indexing="ij",
    )
    dy = to_view.vertical_12 if to_view.vertical_12 is not None else torch.zeros_like(d)
    x3, y3 = xx + d, yy + dy
    # to_seed2's disparity and validity read at (y3, x3) in one call (border padding).
    read = warp_by_flow(
        torch.stack([to_seed2.disparity_12, to_seed2.valid_12.to(d.dtype)], 1), torch.stack([dy, d], 1)
    )
    x2, trusted = x3 + read[:, 0], read[:, 1] > 0.999
    # A point that lands outside the view has no match there (border padding would invent one).
    inside = (x3 >= 0) & (x3 <= w - 1) & (y3 >= 0) & (y3 <= h - 1)
    use = foreground.to(d.device) & to_view.valid_12 & trusted & inside
    return xx.expand_as(x3).reshape(n, -1), x2.reshape(n, -1), x3.reshape(n, -1), use.reshape(n, -1)
