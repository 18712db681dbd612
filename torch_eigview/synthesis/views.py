"""From a few seed views of one object to its dense set of views: :func:`synthesize_views`,
each angle from one seed pair (:func:`pair_of`); see the package's docstring."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from torch_eigview.check import as_angle_tensor, check_int
from torch_eigview.geometry.angles import pair_angles, seed_angles
from torch_eigview.synthesis.options import SynthesisOptions
from torch_eigview.synthesis.seed_pairs import PairGeometry, check_seeds, pair_geometry
from torch_eigview.warp.normalize import normalize_extent, resolve_extent, seed_foreground
from torch_eigview.warp.novel_view import NovelViewWarp

__all__ = ["SynthesizedViews", "pair_of", "synthesize_views"]


@dataclass
class SynthesizedViews:
    """The views of one object.

    Attributes:
        views: (T, C, H, W) synthesized views.
        thetas: (T,) their angles in degrees from the first seed view.
        elevations: one elevation (degrees) per seed pair.
        seconds: time spent in ``"correspondence"`` and ``"synthesis"``.
        pairs: (T,) int64, the seed pair each view comes from (:func:`pair_of`): n for
            seeds n and n + 1.
    """

    views: torch.Tensor
    thetas: torch.Tensor
    elevations: list[float]
    seconds: dict[str, float] = field(default_factory=dict)
    pairs: torch.Tensor = field(default_factory=lambda: torch.empty(0, dtype=torch.long))


def pair_of(thetas: object, alpha: float | Sequence[float], n_seeds: int) -> torch.Tensor:
    """The seed pair that synthesizes each angle (see the module's docstring).

    Args:
        thetas: (T,) angles in degrees from the first seed view.
        alpha: angle between consecutive seed views in degrees, or one angle per pair
            (α_1 … α_(m−1), positive).
        n_seeds: number of seed views m (>= 2), at 0, α_1, α_1 + α_2, ….

    Returns:
        (T,) int64: n for the pair of seeds n and n + 1; with one α,
        ``clamp(floor(θ / α), 0, m − 2)``.

    Example:
        >>> pair_of([-5.0, 0.0, 9.0, 10.0, 25.0], 10.0, 3).tolist()
        [0, 0, 0, 1, 1]
        >>> pair_of([-5.0, 9.0, 10.0, 25.0], [10.0, 20.0], 3).tolist()
        [0, 0, 1, 1]
    """
    n_seeds = check_int(n_seeds, "n_seeds", minimum=2)
    return _pair_index(as_angle_tensor(thetas, "thetas", dtype=torch.float64), pair_angles(alpha, n_seeds))


def _pair_index(theta: torch.Tensor, steps: list[float]) -> torch.Tensor:
    """:func:`pair_of` for validated angles (T,) and per-pair angles."""
    last = len(steps) - 1
    if len(set(steps)) == 1:  # one alpha, either sign
        return torch.clamp(torch.floor(theta.double() / steps[0]), 0, last).long()
    starts = torch.tensor(seed_angles(steps), dtype=torch.float64)
    return torch.clamp(torch.searchsorted(starts, theta.double(), right=True) - 1, 0, last).long()


def synthesize_views(
    seeds: torch.Tensor,
    alpha: float | Sequence[float],
    thetas: object,
    options: SynthesisOptions | None = None,
    geometry: list[PairGeometry] | None = None,
    masks: torch.Tensor | None = None,
) -> SynthesizedViews:
    """Synthesizes the views of one object at ``thetas`` from seed views 0, α, 2α, ….

    Each angle is synthesized by one seed pair, :func:`pair_of`'s: the pair whose sector
    holds it, or the pair nearest in angle before the first and past the last seed.

    Args:
        seeds: (V, C, H, W) seed views, V >= 2, at angles 0, α, …, (V − 1)·α.
        alpha: angle between consecutive seed views in degrees, or Sec. 4.1's α_n, one
            per consecutive pair (V − 1 positive angles: the seeds at 0, α_1,
            α_1 + α_2, …).
        thetas: (T,) novel angles in degrees from the first seed view.
        options: :class:`SynthesisOptions`.
        geometry: the result of :func:`pair_geometry` for these seeds, if already computed.
        masks: optional (V, H, W) bool foreground masks of the seeds (a segmentation's or
            :class:`~torch_eigview.datasets.background.BackgroundModel`'s, the seeds'
            background already set to 0): they replace the ``options.background``
            threshold in silhouette-aware sampling and size normalization.

    Returns:
        :class:`SynthesizedViews` with views in the order of ``thetas``.

    Raises:
        ValueError: fewer than 2 seeds; a number of angles other than V − 1; seed angles
            that do not increase (an α_n <= 0) or coincide (α a multiple of 180); a span
            of 180 degrees or more; a seed mask that is all background.
    """
    opts = options or SynthesisOptions()
    seeds, steps = check_seeds(seeds, alpha)
    starts = seed_angles(steps)
    theta = as_angle_tensor(thetas, "thetas")
    n_pairs = seeds.shape[0] - 1
    masks = None if masks is None else seed_foreground(seeds, masks, opts.background, require_object=True)
    foreground = seed_foreground(seeds, masks, opts.background)  # (V, H, W): the masks, else the threshold
    extent = resolve_extent(opts.extent, foreground)
    if geometry is None:
        geometry = pair_geometry(seeds, alpha, opts, masks)
    elif len(geometry) != n_pairs:
        raise ValueError(f"geometry must hold one record per seed pair ({n_pairs}), got {len(geometry)}")
    pair = _pair_index(theta, steps)
    out = seeds.new_empty((theta.numel(), *seeds.shape[1:]))
    seconds = {"correspondence": sum(g.seconds for g in geometry), "synthesis": 0.0}
    grad = torch.is_grad_enabled() and seeds.requires_grad
    for n, geo in enumerate(geometry):
        t0 = time.perf_counter()
        sel = (pair == n).nonzero().flatten()
        if sel.numel() == 0:
            continue
        warp = NovelViewWarp(
            steps[n], opts.center, max_stretch=opts.max_stretch, elevation=geo.elevation, blend=opts.blend
        )
        pair_seeds = seeds[n : n + 2, None]  # (S=2, B=1, C, H, W)
        fg = foreground[n : n + 2, None]
        sil = fg if opts.silhouette else None
        # The rows where a warped source is not zero (the foreground channel included): the
        # maps are built for the target rows that can reach them, the other rows are 0 (the
        # same values). Not where the seeds take gradients, which those rows' zeros carry,
        # nor off the CPU, where the band's bounds would cost host round trips per pair.
        nonzero = fg if opts.silhouette else fg | (pair_seeds != 0).any(dim=2)
        support = None if grad or seeds.device.type != "cpu" else nonzero.any(dim=-1).any(dim=0)
        maps = warp.maps(geo.correspondence, theta[sel] - starts[n], support=support)
        if extent:
            # The foreground mask rides along as one more channel: one warp for both.
            channel = fg.to(seeds.dtype)[:, :, None]
            warped = warp.apply_maps(maps, torch.cat([pair_seeds, channel], dim=2), sil)[0]
            views = normalize_extent(warped[:, :-1], warped[:, -1] > 0.5)
        else:
            views = warp.apply_maps(maps, pair_seeds, sil)[0]
        out[sel] = views
        seconds["synthesis"] += time.perf_counter() - t0
    return SynthesizedViews(out, theta, [g.elevation for g in geometry], seconds, pair)
