"""From a few seed views of one object to its dense set of views (Secs. 3 and 4.1).

The seed views are at 0, α, 2α, …, (m − 1)·α (degrees; α may be negative), or at
0, α_1, α_1 + α_2, … with one positive angle α_n per consecutive pair (Sec. 4.1). Each
consecutive pair n (seeds n and n + 1, 0 <= n <= m − 2) synthesizes the angles of its own
sector, with the pair's own angles as reference, so A is the concatenation
[G1C1 … G(m−1)C(m−1)] of Sec. 4.1 in its direct form. Every synthesized view comes from
exactly one pair (:func:`pair_of`):

- an angle between two seeds, n·α <= θ < (n + 1)·α, from pair n, which interpolates;
- an angle before the first seed, from pair 0, and one at or past the last seed, from
  pair m − 2: the pair nearest in angle extrapolates on each side;
- an interior seed's own angle n·α, from pair n (its first view). Pair n − 1 gives the
  same image there (its second view: the map at a seed's own angle is the identity and
  needs no correspondence; with a tilted camera up to float rounding in the image's
  first and last rows), so the views are continuous across every seam. The pairs are
  not blended (on COIL-20 a cross-fade across the middle seed changed no recognition).

Each pair keeps its own elevation estimate (``elevation="auto"``), from its own flow.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from torch_eigview.check import (
    as_angle_tensor,
    check_finite,
    check_float_tensor,
    check_int,
    check_ndim,
    check_number,
    check_positive,
)
from torch_eigview.geometry.angles import pair_angles, seed_angles
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.flow import METHODS as FLOW_METHODS
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.pose import estimate_elevation
from torch_eigview.warp.base import BLENDS
from torch_eigview.warp.normalize import normalize_extent, resolve_extent, seed_foreground
from torch_eigview.warp.novel_view import NovelViewWarp

__all__ = [
    "MAX_AUTO_ELEVATION",
    "ElevationFallbackWarning",
    "PairGeometry",
    "SynthesisOptions",
    "SynthesizedViews",
    "object_geometries",
    "pair_geometry",
    "pair_of",
    "synthesize_views",
]

_FAST_TVL1 = {"num_warp": 3, "num_iter": 5}
#: The largest absolute elevation (degrees) an "auto" estimate may have: what NovelViewWarp
#: accepts, strictly below 90.
MAX_AUTO_ELEVATION = 89.0


class ElevationFallbackWarning(UserWarning):
    """``elevation="auto"`` could not measure a seed pair's elevation and used 0."""


@dataclass(frozen=True)
class SynthesisOptions:
    """How seed views become novel views.

    Attributes:
        flow: the correspondences: TV-L1 optical flow, ``"tvl1"`` (in torch, batched) or
            ``"tvl1-skimage"`` (scikit-image's, the reference), scikit-image's ``"ilk"``, or
            ``"rows"``, semi-global matching along the epipolar lines
            (:func:`~torch_eigview.geometry.row_matcher.match_rows`, given each pair's
            α and ``center``).
        threshold: forward–backward consistency tolerance in pixels.
        elevation: camera elevation in degrees (0: the paper's orthographic camera, rows
            stay rows), or ``"auto"`` to measure it per seed pair from the vertical flow; a
            pair whose flow gives no trusted foreground match, or a fit at
            ``MAX_AUTO_ELEVATION`` or beyond (saturated), falls back to 0 with an
            :class:`ElevationFallbackWarning`.
        extent: size-normalize each synthesized view as the data set's images are (COIL's
            processed set is): True, False or ``"auto"``
            (:func:`~torch_eigview.warp.normalize.resolve_extent`).
        background: intensity below which a pixel is background (``extent``, elevation fit).
        center: column of the rotation axis, default the image's centre column.
        max_stretch: see :class:`~torch_eigview.warp.novel_view.NovelViewWarp`.
        flow_options: keyword arguments for the scikit-image flow function. By default
            TV-L1 runs 3 warps of 5 iterations (scikit-image's defaults are 5 and 10):
            3x faster, and on COIL-20 as accurate (see the README).
        blend: how the two seeds of a pair share the pixels both see, ``"linear"`` or
            ``"nearest"`` (see :class:`~torch_eigview.warp.novel_view.NovelViewWarp`).
        silhouette: silhouette-aware sampling: only the seeds' foreground pixels
            (``background``) enter a synthesized pixel, renormalized, and a pixel less
            than half covered by them is background (``NovelViewWarp.apply_maps`` with
            ``masks``); off, a silhouette pixel mixes object and background. The mask is
            ``synthesize_views``'s ``masks``, else the ``background`` threshold (then
            object pixels darker than it count as background).
    """

    flow: str = "tvl1"
    threshold: float = 1.0
    elevation: float | str = "auto"
    extent: bool | str = "auto"
    background: float = 0.05
    center: float | None = None
    max_stretch: float = 3.0
    flow_options: dict[str, object] | None = None
    blend: str = "linear"
    silhouette: bool = False

    def flow_kwargs(self) -> dict[str, object]:
        """Keyword arguments for the scikit-image flow: ``flow_options``, else a fast preset."""
        if self.flow_options is not None:
            return dict(self.flow_options)
        return dict(_FAST_TVL1) if self.flow in ("tvl1", "tvl1-skimage") else {}

    def __post_init__(self) -> None:
        if self.flow not in FLOW_METHODS:
            raise ValueError(f"flow must be one of {FLOW_METHODS}, got {self.flow!r}")
        if isinstance(self.elevation, str):
            if self.elevation != "auto":
                raise ValueError(f"elevation must be a number of degrees or 'auto', got {self.elevation!r}")
        elif not abs(check_number(self.elevation, "elevation")) < 90:  # NaN fails too
            raise ValueError(f"elevation={self.elevation!r} must be an angle in degrees in (-90, 90)")
        if self.extent != "auto" and not isinstance(self.extent, bool):
            raise ValueError(f"extent must be True, False or 'auto', got {self.extent!r}")
        if not isinstance(self.silhouette, bool):
            raise TypeError(f"silhouette must be a bool, got {type(self.silhouette).__name__}")
        if self.blend not in BLENDS:
            raise ValueError(f"blend must be one of {BLENDS}, got {self.blend!r}")
        check_positive(self.threshold, "threshold")
        if not check_number(self.max_stretch, "max_stretch") > 0:  # inf: no depth jumps
            raise ValueError(f"max_stretch={self.max_stretch!r} must be a number > 0")
        if not math.isfinite(check_number(self.background, "background")):
            raise ValueError(f"background={self.background!r} must be finite")
        if self.center is not None and not math.isfinite(check_number(self.center, "center")):
            raise ValueError(f"center={self.center!r} must be finite or None")


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


@dataclass(frozen=True)
class PairGeometry:
    """What one seed pair contributes before any warping: correspondences and elevation."""

    correspondence: Correspondence
    elevation: float
    seconds: float


def check_seeds(seeds: torch.Tensor, alpha: object) -> tuple[torch.Tensor, list[float]]:
    """Validates seed views and their angles.

    Args:
        seeds: (V, C, H, W) finite float seed views, V >= 2.
        alpha: angle between consecutive seed views in degrees, or one per pair (V − 1).

    Returns:
        ``(seeds, steps)``: the seeds and the V − 1 per-pair angles α_n.

    Raises:
        TypeError: ``seeds`` is not a float tensor.
        ValueError: a bad shape, fewer than 2 views, non-finite values or bad angles.
    """
    seeds = check_float_tensor(seeds, "seeds")
    check_ndim(seeds, "seeds", (4,), "(V, C, H, W)")
    if seeds.shape[0] < 2:
        raise ValueError(f"seeds must hold at least 2 views, got V={seeds.shape[0]}")
    if min(seeds.shape[1:]) < 1:
        raise ValueError(f"seeds must have C, H, W >= 1, got shape {tuple(seeds.shape)}")
    check_finite(seeds, "seeds")
    return seeds, pair_angles(alpha, seeds.shape[0])


def pair_geometry(
    seeds: torch.Tensor,
    alpha: float | Sequence[float],
    options: SynthesisOptions | None = None,
    masks: torch.Tensor | None = None,
) -> list[PairGeometry]:
    """Correspondences (and the elevation) of each consecutive seed pair.

    This is the optical-flow stage, kept apart so that a caller can run it ahead (for
    example for the next object, in a worker thread, while this one is warped).

    Args:
        seeds: (V, C, H, W) seed views at 0, α, …, (V − 1)·α.
        alpha: angle between consecutive seed views in degrees, or one per pair (V − 1).
        options: :class:`SynthesisOptions`.
        masks: optional (V, H, W) bool seed masks, in place of the ``options.background`` threshold.

    Returns:
        V − 1 :class:`PairGeometry` records.
    """
    opts = options or SynthesisOptions()
    seeds, steps = check_seeds(seeds, alpha)
    fg = seed_foreground(seeds, masks, opts.background)
    n_pairs = seeds.shape[0] - 1
    if opts.flow == "tvl1":  # batched: every pair (both directions) in one call
        t0 = time.perf_counter()
        batch = estimate_correspondence(
            seeds[:-1], seeds[1:], method="tvl1", threshold=opts.threshold, **opts.flow_kwargs()
        )
        corrs = list(batch)
        seconds = [(time.perf_counter() - t0) / n_pairs] * n_pairs
    else:
        corrs, seconds = [], []
        for n in range(n_pairs):
            t0 = time.perf_counter()
            kwargs = opts.flow_kwargs()
            if opts.flow == "rows":
                kwargs = {"alpha": steps[n], "center": opts.center, **kwargs}
            corrs.append(
                estimate_correspondence(
                    seeds[n : n + 1],
                    seeds[n + 1 : n + 2],
                    method=opts.flow,
                    threshold=opts.threshold,
                    **kwargs,
                )
            )
            seconds.append(time.perf_counter() - t0)
    out = []
    for n, corr in enumerate(corrs):
        t0 = time.perf_counter()
        elevation = opts.elevation
        if elevation == "auto":
            elevation = _auto_elevation(corr, steps[n], fg[n : n + 1], opts.center, n)
        out.append(PairGeometry(corr, float(elevation), seconds[n] + time.perf_counter() - t0))
    return out


def object_geometries(
    objects: Sequence[torch.Tensor], alpha: float | Sequence[float], options: SynthesisOptions | None = None
) -> list[list[PairGeometry]]:
    """:func:`pair_geometry` of many objects; with ``flow="tvl1"`` every seed pair of every
    object (both directions) is one batched flow call, on the seeds' device.

    Args:
        objects: per object its (V, C, H, W) seed views, the same shape for all.
        alpha: angle between consecutive seed views in degrees, or one per pair (V − 1).
        options: :class:`SynthesisOptions`.

    Returns:
        Per object its V − 1 :class:`PairGeometry` records (each pair's seconds a share of
        the batch's), for :func:`synthesize_views`'s ``geometry``.
    """
    opts = options or SynthesisOptions()
    checked = [check_seeds(s, alpha)[0] for s in objects]
    if opts.flow != "tvl1" or len(checked) < 2:
        return [pair_geometry(s, alpha, opts) for s in checked]
    if len({tuple(s.shape) for s in checked}) > 1:
        raise ValueError(
            f"objects must share one seed shape, got {sorted({tuple(s.shape) for s in checked})}"
        )
    steps = pair_angles(alpha, checked[0].shape[0])
    t0 = time.perf_counter()
    batch = estimate_correspondence(
        torch.cat([s[:-1] for s in checked]),
        torch.cat([s[1:] for s in checked]),
        method="tvl1",
        threshold=opts.threshold,
        **opts.flow_kwargs(),
    )
    corrs = list(batch)
    n_pairs = len(steps)
    share = (time.perf_counter() - t0) / len(corrs)
    out = []
    for o, s in enumerate(checked):
        fg = seed_foreground(s, None, opts.background)
        geos = []
        for n in range(n_pairs):
            elevation = opts.elevation
            if elevation == "auto":
                elevation = _auto_elevation(corrs[o * n_pairs + n], steps[n], fg[n : n + 1], opts.center, n)
            geos.append(PairGeometry(corrs[o * n_pairs + n], float(elevation), share))
        out.append(geos)
    return out


def _auto_elevation(
    corr: Correspondence, alpha: float, mask: torch.Tensor, center: float | None, pair: int
) -> float:
    """The elevation measured from one pair's vertical flow, or 0 (the paper's untilted
    camera) with a warning when the flow cannot give one.

    Two cases fall back: no trusted foreground correspondence to fit (a featureless or
    badly matched pair), and a fit that saturates at ±90 degrees, which no turntable camera
    has and the warp refuses; both are unreliable flow, not a tilted camera, so the pair is
    synthesized as the untilted orthographic model, as with ``elevation=0``.
    """
    try:
        elevation = float(estimate_elevation(corr, alpha, center=center, mask=mask)[0])
    except ValueError as exc:  # no trusted pixel with depth under the mask
        why = str(exc)
    else:
        if math.isfinite(elevation) and abs(elevation) < MAX_AUTO_ELEVATION:
            return elevation
        why = (
            f"the fit gave elevation={elevation:g}, outside (-{MAX_AUTO_ELEVATION:g}, {MAX_AUTO_ELEVATION:g})"
        )
    warnings.warn(
        f"seed pair {pair}: elevation='auto' could not be measured ({why}); using elevation=0, "
        "the untilted camera (pass a number of degrees to choose another)",
        ElevationFallbackWarning,
        stacklevel=3,
    )
    return 0.0


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
    for n, geo in enumerate(geometry):
        t0 = time.perf_counter()
        sel = (pair == n).nonzero().flatten()
        if sel.numel() == 0:
            continue
        warp = NovelViewWarp(
            steps[n], opts.center, max_stretch=opts.max_stretch, elevation=geo.elevation, blend=opts.blend
        )
        maps = warp.maps(geo.correspondence, theta[sel] - starts[n])
        pair_seeds = seeds[n : n + 2, None]  # (S=2, B=1, C, H, W)
        fg = foreground[n : n + 2, None]
        sil = fg if opts.silhouette else None
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
