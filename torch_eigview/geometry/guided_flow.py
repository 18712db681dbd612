"""TV-L1 guided by the row matcher: correspondences for seed views far apart in angle.

TV-L1's pyramid (:func:`~torch_eigview.geometry.tvl1.tvl1_flow`) follows a displacement
of a few pixels at its coarsest level, about ten at full size on 128 × 128 views. Between
two turntable views α apart a surface point at depth Z from the axis moves by up to
``|Z sin α|`` pixels: 45 px for Z = 64 at α = 45°, where TV-L1 alone finds almost none of
the motion (on COIL-20, 45° pairs: its disparities are 0.07 of those chained through the
real views 5° apart, ``python -m torch_eigview.apps.diagnose correspondence``).

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

from torch_eigview.check import check_alpha
from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.geometry.row_matcher import match_rows
from torch_eigview.geometry.tvl1 import tvl1_flow

__all__ = ["MIN_SIDE", "ROW_OPTIONS", "TVL1_OPTIONS", "guided_tvl1"]

#: The smallest image side the row matcher takes (its line model is searched at quarter
#: resolution); on smaller views, whose displacements are a pixel or two, the guided flow is
#: TV-L1 alone.
MIN_SIDE = 4

#: Keyword arguments of :func:`guided_tvl1` that go to the row matcher.
ROW_OPTIONS = ("elevation", "depth", "cost", "patch", "p1", "p2")
#: Keyword arguments of :func:`guided_tvl1` that go to TV-L1.
TVL1_OPTIONS = tuple(p for p in inspect.signature(tvl1_flow).parameters if p not in ("reference", "moving"))


def _sample(fields: torch.Tensor, dx: torch.Tensor, dy: torch.Tensor) -> torch.Tensor:
    """(N, F, H, W) ``fields`` sampled bilinearly at (x + dx, y + dy), border padding.

    ``dx`` and ``dy`` are (N, H, W) displacements on the fields' own pixel grid.
    """
    h, w = fields.shape[-2:]
    xs = torch.arange(w, dtype=dx.dtype, device=dx.device)
    ys = torch.arange(h, dtype=dx.dtype, device=dx.device)[:, None]
    grid = torch.stack([(xs + dx) * (2.0 / max(w - 1, 1)) - 1, (ys + dy) * (2.0 / max(h - 1, 1)) - 1], dim=-1)
    return F.grid_sample(fields, grid, mode="bilinear", padding_mode="border", align_corners=True)


def guided_tvl1(
    view1: torch.Tensor,
    view2: torch.Tensor,
    alpha: float,
    *,
    center: float | None = None,
    threshold: float = 1.0,
    **options: object,
) -> Correspondence:
    """Correspondences of turntable views α apart: the row matcher's matches refined by TV-L1.

    Args:
        view1: (B, C, H, W) first seed views (channels averaged to gray).
        view2: same shape, the views turned by ``alpha``.
        alpha: angle from view 1 to view 2 in degrees.
        center: column of the rotation axis (the row matcher's), default ``(W - 1) / 2``.
        threshold: forward–backward tolerance in pixels for the validity masks.
        **options: :data:`ROW_OPTIONS` for the row matcher (``depth``, ``elevation``, …)
            and :data:`TVL1_OPTIONS` for TV-L1 (``num_warp``, ``num_iter``, …).

    Returns:
        A :class:`Correspondence` (B, H, W) in the views' dtype and device, with the
        composed vertical flow in ``vertical_12`` and ``vertical_21``.

    Raises:
        ValueError: an option neither the row matcher nor TV-L1 takes, or what either
            raises for its own arguments.
    """
    unknown = sorted(set(options) - set(ROW_OPTIONS) - set(TVL1_OPTIONS))
    if unknown:
        raise ValueError(
            f"flow options {unknown} are not options of the guided flow: it takes the row matcher's "
            f"{list(ROW_OPTIONS)} and TV-L1's {list(TVL1_OPTIONS)}"
        )
    row_kw = {k: v for k, v in options.items() if k in ROW_OPTIONS}
    tv_kw = {k: v for k, v in options.items() if k in TVL1_OPTIONS}
    b, _, h, w = view1.shape
    zeros = torch.zeros(2 * b, h, w, device=view1.device)
    if min(h, w) >= MIN_SIDE:
        prior = match_rows(view1, view2, alpha, center=center, threshold=threshold, **row_kw)  # type: ignore[arg-type]
        px = torch.cat([prior.disparity_12, prior.disparity_21]).float()
        py = zeros
        if prior.vertical_12 is not None and prior.vertical_21 is not None:
            py = torch.cat([prior.vertical_12, prior.vertical_21]).float()
    else:  # too small for the row matcher's line model: no prior, TV-L1 alone
        check_alpha(alpha)
        px = py = zeros
    with torch.no_grad():
        gray = torch.cat([view1, view2]).detach().mean(dim=1, keepdim=True).float()
        # Each view's partner warped onto its grid by the prior: view 2 onto view 1, and back.
        other = torch.cat([gray[b:], gray[:b]])
        warped = _sample(other, px, py)[:, 0]
        residual = tvl1_flow(gray[:, 0], warped, **tv_kw)  # type: ignore[arg-type]  # (2B, 2, H, W)
        ry, rx = residual[:, 0], residual[:, 1]
        moved = _sample(torch.stack([px, py], dim=1), rx, ry)
        dx, dy = (rx + moved[:, 0]), (ry + moved[:, 1])
        dx, dy = dx.to(view1.dtype), dy.to(view1.dtype)
    if not bool(torch.isfinite(dx).all() & torch.isfinite(dy).all()):
        raise ValueError("the guided flow between view1 and view2 diverged (NaN or infinite flow)")
    corr = correspondence_from_disparity(dx[:b], dx[b:], threshold=threshold)
    return dataclasses.replace(corr, vertical_12=dy[:b], vertical_21=dy[b:])
