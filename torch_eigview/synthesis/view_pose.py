"""The pose of a view between two seed views by geometry: two flows and Eq. 2.

:func:`view_angles` measures the correspondences the synthesis would (``options.flow``)
between seed 1 and each view and between the view and seed 2, and fits Eq. 2's angle to
them (:mod:`torch_eigview.geometry.view_pose`). :func:`seed_pair_poses` does it for views
of one object whose rough poses are known (a recognizer's), each with the seed pair whose
sector holds it.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import torch

from torch_eigview.check import check_alpha, check_finite, check_float_tensor, check_ndim
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.view_pose import chain_columns, fit_view_angle
from torch_eigview.synthesis.options import SynthesisOptions
from torch_eigview.warp.normalize import seed_foreground

__all__ = ["seed_pair_poses", "view_angles"]


def view_angles(
    views: torch.Tensor,
    seeds: torch.Tensor,
    alpha: float,
    options: SynthesisOptions | None = None,
    seed_mask: torch.Tensor | None = None,
) -> torch.Tensor:
    """The angle of each view between two seed views of its object, by Eq. 2.

    Two flows per view, ``options.flow`` as the synthesis runs it (both directions, its
    forward–backward check): seed 1 → view and view → seed 2, each given the mid-sector
    angle ``alpha / 2`` (the views' angles are what is sought). A seed-1 foreground pixel
    trusted by the first is followed into the view (its vertical motion included), the
    second is read there, and the three columns enter :func:`fit_view_angle`, each point
    weighted by seed 1's horizontal derivative there (the aperture problem: see ``_column_weight``).

    Args:
        views: (N, C, H, W) views of the object the seeds show.
        seeds: (2, C, H, W) its seed views at 0 and ``alpha``.
        alpha: the angle between the seeds in degrees.
        options: :class:`~torch_eigview.synthesis.SynthesisOptions` (the flow, its
            settings, the background threshold).
        seed_mask: optional (H, W) bool foreground of seed 1, in place of the threshold.

    Returns:
        (N,) float64 angles in degrees from seed 1; NaN where a view has too few trusted
        points (:data:`~torch_eigview.geometry.view_pose.MIN_POINTS`; a point where seed 1
        does not vary along its row does not count) or a degenerate fit
        (:func:`~torch_eigview.geometry.view_pose.fit_view_angle`).

    Raises:
        TypeError / ValueError: views and seeds of other shapes or kinds, a bad ``alpha``.
    """
    opts = options or SynthesisOptions()
    views = check_float_tensor(views, "views")
    seeds = check_float_tensor(seeds, "seeds")
    check_ndim(views, "views", (4,), "(N, C, H, W)")
    check_ndim(seeds, "seeds", (4,), "(2, C, H, W)")
    if seeds.shape[0] != 2 or seeds.shape[1:] != views.shape[1:]:
        raise ValueError(
            f"seeds must have shape (2, {', '.join(map(str, views.shape[1:]))}) to match views, "
            f"got {tuple(seeds.shape)}"
        )
    alpha = check_alpha(alpha)
    n, _, h, w = views.shape
    if n == 0:
        return torch.empty(0, dtype=torch.float64, device=views.device)
    if seed_mask is not None and (not isinstance(seed_mask, torch.Tensor) or seed_mask.shape != (h, w)):
        got = tuple(seed_mask.shape) if isinstance(seed_mask, torch.Tensor) else type(seed_mask).__name__
        raise ValueError(
            f"seed_mask must be an ({h}, {w}) bool tensor, the views' height and width, got {got}"
        )
    mask = None if seed_mask is None else seed_mask.to(seeds.device)[None]
    fg = seed_foreground(seeds[:1], mask, opts.background)[0]
    kwargs = opts.flow_kwargs(alpha / 2)
    s1, s2 = seeds[:1].expand_as(views), seeds[1:].expand_as(views)
    to_view = estimate_correspondence(s1, views, method=opts.flow, threshold=opts.threshold, **kwargs)
    to_seed2 = estimate_correspondence(views, s2, method=opts.flow, threshold=opts.threshold, **kwargs)
    return fit_view_angle(*chain_columns(to_view, to_seed2, fg), alpha, weight=_column_weight(seeds[0]))


def _column_weight(image: torch.Tensor) -> torch.Tensor:
    """(H·W,) how well each pixel's column displacement can be measured: the magnitude of
    the image's horizontal derivative (central differences, the channels' mean; 0 in the
    first and last column). A flow moves a pixel along its row freely where the row does
    not vary (the aperture problem): there it tends to stay put, which pulls a view's
    fitted angle towards the seed it is nearer (on COIL-20, seeds 45° apart, true sector:
    median error 2.43° against 2.67° unweighted, 8 objects).

    Args:
        image: (C, H, W) the view whose pixels are followed (seed 1).
    """
    gx = torch.zeros_like(image)
    gx[:, :, 1:-1] = (image[:, :, 2:] / 2 - image[:, :, :-2] / 2).abs()  # halved first: no overflow
    return gx.mean(dim=0).reshape(-1)


def seed_pair_poses(
    views: torch.Tensor,
    rough: torch.Tensor,
    seeds: torch.Tensor,
    seed_poses: Sequence[float],
    *,
    closed: bool = False,
    options: SynthesisOptions | None = None,
) -> torch.Tensor:
    """Poses of views of one object by :func:`view_angles`, each from the seed pair whose
    sector holds its rough pose.

    The pair is the one whose seeds enclose the rough pose (going round the circle when
    ``closed``). Where Eq. 2 puts the view outside that sector, the view is measured again
    with the neighbouring pair on that side, and that pose is kept if it falls inside the
    neighbour's sector; else (no neighbour, or it disagrees too) the first measurement
    stands: Eq. 2 holds past the seeds (clamping to the sector instead raised the mean
    error on COIL-20 objects 1–3, seeds 10° apart, from 1.21° to 2.18°). A view the fit
    cannot place keeps its rough pose, and so does a
    view whose rough pose lies before the first seed or past the last (open seeds): there
    Eq. 2 extrapolates, its coefficients grow as 1 / sin α, and on COIL-20 (seeds 10°
    apart, views up to 45° away) the fitted poses were worse than the appearance's.

    Args:
        views: (N, C, H, W) views of the object.
        rough: (N,) rough poses in degrees (a recognizer's nearest or interpolated pose).
        seeds: (V, C, H, W) the object's seed views, V >= 2.
        seed_poses: their V poses in degrees, increasing, less than 360 apart in all.
        closed: the seeds go round the whole circle (pair V − 1 joins the last seed to
            the first); needs V >= 3.
        options: the synthesis options (the flow and its settings).

    Returns:
        (N,) float64 poses in degrees, in [0, 360) when ``closed``, else on the scale of
        ``seed_poses`` (a rough pose is taken as the turn nearest the seeds' middle).

    Raises:
        TypeError / ValueError: shapes that do not match, poses that do not increase.
    """
    views = check_float_tensor(views, "views")
    seeds = check_float_tensor(seeds, "seeds")
    check_ndim(views, "views", (4,), "(N, C, H, W)")
    check_ndim(seeds, "seeds", (4,), "(V, C, H, W)")
    rough = check_float_tensor(rough, "rough")
    check_finite(rough, "rough")
    if rough.shape != views.shape[:1]:
        raise ValueError(
            f"rough must have shape ({views.shape[0]},), one pose per view, got {tuple(rough.shape)}"
        )
    if seeds.shape[1:] != views.shape[1:]:
        raise ValueError(
            f"seeds must have shape (V, {', '.join(map(str, views.shape[1:]))}) to match views, got {tuple(seeds.shape)}"
        )
    poses = [float(p) for p in seed_poses]
    if not all(math.isfinite(p) for p in poses):
        raise ValueError(f"seed_poses must be finite degrees, got {poses}")
    v = seeds.shape[0]
    if len(poses) != v or v < (3 if closed else 2):
        raise ValueError(
            f"seed_poses must hold one pose per seed view ({v}, at least {3 if closed else 2}), got {len(poses)}"
        )
    if any(b <= a for a, b in itertools.pairwise(poses)) or poses[-1] - poses[0] >= 360:
        raise ValueError(f"seed_poses must increase and span less than 360 degrees, got {poses}")
    n_pairs = v if closed else v - 1
    ends = [*poses, poses[0] + 360.0] if closed else poses
    start = torch.tensor(ends[:-1], dtype=torch.float64)
    p = rough.double().cpu()
    # On the seeds' scale: the circle from the first seed, else the turn nearest the span's middle.
    mid = (poses[0] + poses[-1]) / 2
    p = (
        poses[0] + torch.remainder(p - poses[0], 360.0)
        if closed
        else mid + torch.remainder(p - mid + 180.0, 360.0) - 180.0
    )
    pair = torch.searchsorted(start, p, right=True) - 1
    out = p.clone()
    if not closed:  # only views within the seeds' span: -1 marks the others
        pair = torch.where((p >= poses[0]) & (p <= poses[-1]), pair.clamp(0, n_pairs - 1), -1)

    def measure(k: int, sel: torch.Tensor) -> tuple[torch.Tensor, float, float]:
        k %= n_pairs
        alpha = ends[k + 1] - ends[k]
        two = seeds[[k, (k + 1) % v]]
        return (
            view_angles(views[sel.to(views.device)], two, check_alpha(alpha), options).cpu(),
            alpha,
            ends[k],
        )

    for k in pair.unique().tolist():
        if k < 0:
            continue
        sel = (pair == k).nonzero()[:, 0]
        theta, alpha, base = measure(k, sel)
        out[sel] = torch.where(theta.isnan(), out[sel], base + theta)
        for side in (-1, 1):
            beyond = sel[(theta < 0) if side < 0 else (theta > alpha)]
            if beyond.numel() == 0 or (not closed and not 0 <= k + side < n_pairs):
                continue
            theta2, alpha2, base2 = measure(k + side, beyond)
            inside = (theta2 >= 0) & (theta2 <= alpha2)
            out[beyond] = torch.where(inside, base2 + theta2, out[beyond])
    return torch.remainder(out, 360.0) if closed else out
