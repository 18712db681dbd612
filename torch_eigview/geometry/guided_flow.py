"""TV-L1 guided by the row matcher: correspondences for seed views far apart in angle.

TV-L1's pyramid (:func:`~torch_eigview.geometry.tvl1.tvl1_flow`) follows a displacement
of a few pixels at its coarsest level, about ten at full size on 128 × 128 views. Between
two turntable views α apart a surface point at depth Z from the axis moves by up to
``|Z sin α|`` pixels: 45 px for Z = 64 at α = 45°, where TV-L1 alone finds almost none of
the motion (on COIL-20, 45° pairs: its disparities are 0.07 of those chained through the
real views 5° apart, ``python examples/diagnostics/diagnose_flow.py``).

The row matcher (:func:`~torch_eigview.geometry.row_matcher.match_rows`) searches the
whole epipolar range the geometry allows, ``|Z| <= depth``, but in whole labels and with
a left–right check that rejects most pixels at large α. :func:`guided_tvl1` takes its
dense matches (every pixel, trusted or not) as a prior displacement, warps the other view
onto each view's grid with it, lets TV-L1 find the small residual motion between the view
and the warped one, and composes both:

    ``d12(x) = r(x) + prior(x + r(x))``, with ``view1(x) ≈ view2(x + r + prior(x + r))``.

The forward–backward check then runs on the composed disparities, as for the other flows.
"""

from __future__ import annotations

import dataclasses
import inspect

import torch
import torch.nn.functional as F

from torch_eigview.check import check_int, check_view_pair
from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.geometry.row_matcher import check_row_options, epipolar_matches, match_rows
from torch_eigview.geometry.tvl1 import check_range, diverged, tvl1_flow, warp_by_flow

__all__ = ["MIN_SIDE", "PRIOR_SIDE", "ROW_OPTIONS", "TVL1_OPTIONS", "guided_tvl1", "prior_reduction"]

#: The smallest image side the row matcher takes (its line model is searched at quarter
#: resolution); on smaller views, whose displacements are a pixel or two, the guided flow is
#: TV-L1 alone.
MIN_SIDE = 4
#: The default of :func:`guided_tvl1`'s ``prior_side``: the largest side the row matcher's
#: prior is matched at. The matcher's cost volume holds pixels × labels elements, and its
#: labels grow with the width (``W/2 · |sin α|`` each way), so its time and memory grow
#: as the cube of the side: a 512 × 512 pair at full size would cost 64 times a 128 × 128
#: one. At 128 the prior is matched at COIL's own resolution, and on larger views TV-L1's
#: deeper pyramid refines what the prior's coarser steps leave.
PRIOR_SIDE = 128

#: Keyword arguments of :func:`guided_tvl1` that go to the row matcher.
ROW_OPTIONS = tuple(
    p
    for p in inspect.signature(match_rows).parameters
    if p not in ("view1", "view2", "alpha", "center", "threshold")
)
_ROW_DEFAULTS = {
    name: p.default for name, p in inspect.signature(match_rows).parameters.items() if name in ROW_OPTIONS
}
#: Keyword arguments of :func:`guided_tvl1` that go to TV-L1.
TVL1_OPTIONS = tuple(p for p in inspect.signature(tvl1_flow).parameters if p not in ("reference", "moving"))


def prior_reduction(height: int, width: int, prior_side: int = PRIOR_SIDE) -> int:
    """The power of two by which :func:`guided_tvl1` reduces (H, W) views for the row
    matcher's prior: the smallest that brings the larger side to at most ``prior_side``."""
    f = 1
    while max(height, width) > prior_side * f:
        f *= 2
    return f


def _check_views(view1: object, view2: object) -> tuple[torch.Tensor, torch.Tensor]:
    """The two views as finite float (B, C, H, W) tensors of one shape, within TV-L1's range."""
    v1, v2 = check_view_pair(view1, view2)
    if v1.shape[-3] < 1 or v1.shape[-2] < 2 or v1.shape[-1] < 2:
        raise ValueError(f"view1 must have a channel and at least 2 x 2 pixels, got shape {tuple(v1.shape)}")
    check_range(v1, v2, "guided")
    return v1, v2


def guided_tvl1(
    view1: torch.Tensor,
    view2: torch.Tensor,
    alpha: float,
    *,
    center: float | None = None,
    threshold: float = 1.0,
    prior_side: int = PRIOR_SIDE,
    **options: object,
) -> Correspondence:
    """Correspondences of turntable views α apart: the row matcher's matches refined by TV-L1.

    Args:
        view1: (B, C, H, W) or (C, H, W) first seed views (channels averaged to gray).
        view2: same shape, the views turned by ``alpha``.
        alpha: angle from view 1 to view 2 in degrees.
        center: column of the rotation axis (the row matcher's), default ``(W - 1) / 2``.
        threshold: forward–backward tolerance in pixels for the validity masks.
        prior_side: the largest side, in pixels, at which the row matcher's prior is
            matched (:data:`PRIOR_SIDE`, 128, by default): views with a larger side are
            reduced by the smallest power of two that brings it within ``prior_side``
            (:func:`prior_reduction`), their matches scaled back, and TV-L1 refines them
            at full size. The matcher's cost grows as the cube of the side it runs at; a
            larger ``prior_side`` gives a finer prior at that cost, and changes the
            correspondences of views larger than it.
        **options: :data:`ROW_OPTIONS` for the row matcher (``depth``, ``elevation``, …;
            ``depth`` in pixels of the views) and :data:`TVL1_OPTIONS` for TV-L1
            (``num_warp``, ``num_iter``, …).

    Returns:
        A :class:`Correspondence` (B, H, W) in the views' dtype and device, with the
        composed vertical flow in ``vertical_12`` and ``vertical_21``; B = 0 gives an
        empty one. Not differentiable: the views enter detached.

    Raises:
        TypeError: a view that is not a float tensor, or an option of the wrong type.
        ValueError: views of other shapes than (B, C, H, W) / (C, H, W) or that differ,
            non-finite views or values TV-L1 cannot take, an option neither the row
            matcher nor TV-L1 takes, or a bad value of one (checked on views of any size).
    """
    v1, v2 = _check_views(view1, view2)
    prior_side = check_int(prior_side, "prior_side", minimum=1)
    unknown = sorted(set(options) - set(ROW_OPTIONS) - set(TVL1_OPTIONS))
    if unknown:
        raise ValueError(
            f"options {unknown} are neither the row matcher's {list(ROW_OPTIONS)} nor TV-L1's "
            f"{list(TVL1_OPTIONS)}"
        )
    row_kw = {k: v for k, v in options.items() if k in ROW_OPTIONS}
    tv_kw = {k: v for k, v in options.items() if k in TVL1_OPTIONS}
    alpha, cost, patch, tilt = check_row_options(alpha, center, threshold=threshold, **row_kw)
    b, _, h, w = v1.shape
    if b == 0:
        empty = v1.new_empty(0, h, w)
        return Correspondence(empty, empty, empty.bool(), empty.bool(), empty, empty)
    # The row matcher's cost volume grows with the pixels times the labels (W/2 · |sin α|
    # each way): on large views it runs on views reduced by a power of two to at most
    # prior_side, and its matches are scaled back; TV-L1's pyramid, deeper on large views,
    # takes up the prior's coarser steps.
    f = prior_reduction(h, w, prior_side)
    with torch.no_grad():
        # Float32 grayscale, view 1's then view 2's, as the row matcher and TV-L1 take them.
        gray = torch.cat([v1, v2]).detach().mean(dim=1, keepdim=True).float()
        # The prior (2B, 2, H, W), rows first as a flow: view 1's pixels towards view 2, then
        # view 2's towards view 1. Below MIN_SIDE (times the reduction) the row matcher's line
        # model has too few pixels: no prior, TV-L1 alone (such views move by a pixel or two).
        prior = gray.new_zeros(2 * b, 2, h, w)
        if min(h, w) >= MIN_SIDE * f:
            small = F.avg_pool2d(gray, f)[:, 0] if f > 1 else gray[:, 0]
            row = {**_ROW_DEFAULTS, **row_kw}
            c = (w - 1) / 2 if center is None else float(center)
            reach = small.shape[-1] / 2 if row["depth"] is None else float(row["depth"]) / f
            p1, p2 = float(row["p1"]), float(row["p2"])
            dx, dy = epipolar_matches(small, alpha, (c - (f - 1) / 2) / f, reach, tilt, cost, patch, p1, p2)
            prior = torch.stack([dy, dx], dim=1)
            if f > 1:
                prior = F.interpolate(prior, size=(h, w), mode="bilinear", align_corners=False) * f
        # Each view's partner warped onto its grid by the prior: view 2 onto view 1, and back.
        warped = warp_by_flow(torch.cat([gray[b:], gray[:b]]), prior)[:, 0]
        residual = tvl1_flow(gray[:, 0], warped, **tv_kw)  # type: ignore[arg-type]  # (2B, 2, H, W)
        flow = residual + warp_by_flow(prior, residual)
        dy, dx = flow[:, 0].to(v1.dtype), flow[:, 1].to(v1.dtype)
    if not bool(torch.isfinite(dx).all() & torch.isfinite(dy).all()):
        raise diverged("guided", max(float(v1.abs().max()), float(v2.abs().max())))
    corr = correspondence_from_disparity(dx[:b], dx[b:], threshold=threshold)
    return dataclasses.replace(corr, vertical_12=dy[:b], vertical_21=dy[b:])
