"""The geometry of consecutive seed pairs before any warping: correspondences and elevation.

This is the optical-flow stage of :func:`~torch_eigview.synthesis.views.synthesize_views`, kept
apart so that a caller can run it ahead (for another object, in another thread) or batch
it over objects (:func:`object_geometries`).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import torch

import torch_eigview._tuning as _tuning
from torch_eigview.check import check_finite, check_float_tensor, check_int, check_ndim
from torch_eigview.geometry.angles import pair_angles
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.guided_flow import PRIOR_SIDE, prior_reduction
from torch_eigview.geometry.pose import estimate_elevation
from torch_eigview.geometry.row_matcher import volume_size
from torch_eigview.synthesis.options import SynthesisOptions
from torch_eigview.warp.normalize import seed_foreground

__all__ = [
    "MAX_AUTO_ELEVATION",
    "ElevationFallbackWarning",
    "PairGeometry",
    "check_seeds",
    "iter_object_geometries",
    "object_geometries",
    "pair_geometry",
]

#: The largest absolute elevation (degrees) an "auto" estimate may have: what NovelViewWarp
#: accepts, strictly below 90.
MAX_AUTO_ELEVATION = 89.0


#: The flows that :func:`object_geometries` batches over objects: TV-L1 in one call, the
#: row matcher and the guided flow in one call per angle between seeds.
_BATCHED = ("tvl1", "rows", "guided")


class ElevationFallbackWarning(UserWarning):
    """``elevation="auto"`` could not measure a seed pair's elevation and used 0."""


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
    if opts.flow == "tvl1":  # batched: every pair (both directions) in one call
        corrs, seconds = _batched_tvl1([seeds], opts)
    else:
        corrs, seconds = _by_angle([seeds], steps, opts)
    return _with_elevations(seeds, masks, corrs, seconds, steps, opts)


def object_geometries(
    objects: Sequence[torch.Tensor],
    alpha: float | Sequence[float],
    options: SynthesisOptions | None = None,
    masks: Sequence[torch.Tensor | None] | None = None,
) -> list[list[PairGeometry]]:
    """:func:`pair_geometry` of many objects; with ``flow="tvl1"`` every seed pair of every
    object (both directions) is one batched flow call, on the seeds' device, and with
    ``"guided"`` or ``"rows"`` one call per distinct angle between seeds (objects of other
    seed shapes: one object at a time). On the CPU the row matcher's calls take as many
    pairs as their cost volumes allow (``torch_eigview._tuning.FLOW_BATCH_CPU``: a bound
    on a call's memory). The flows treat each pair of a batch on its own: the records are
    those of :func:`pair_geometry` (bit for bit with the guided flow and the row matcher,
    ``tests/test_object_geometries.py``).

    Args:
        objects: per object its (V, C, H, W) seed views, the same shape for all.
        alpha: angle between consecutive seed views in degrees, or one per pair (V − 1).
        options: :class:`SynthesisOptions`.
        masks: per object its (V, H, W) bool seed masks or None (the ``options.background``
            threshold), as :func:`pair_geometry`'s ``masks``.

    Returns:
        Per object its V − 1 :class:`PairGeometry` records (each pair's seconds its share
        of the batched flow plus its own elevation fit), for :func:`synthesize_views`'s
        ``geometry``.
    """
    return list(iter_object_geometries(objects, alpha, options, masks))


def iter_object_geometries(
    objects: Sequence[torch.Tensor],
    alpha: float | Sequence[float],
    options: SynthesisOptions | None = None,
    masks: Sequence[torch.Tensor | None] | None = None,
) -> Iterator[list[PairGeometry]]:
    """:func:`object_geometries` one object at a time: the arguments are checked at the
    call, the batched flows run when the first object's records are asked for, and each
    object's elevation fit when its own records are (its warnings are raised then, so a
    caller can tell whose they are)."""
    opts = options or SynthesisOptions()
    checked = [check_seeds(s, alpha)[0] for s in objects]
    per_mask: list[torch.Tensor | None] = list(masks) if masks is not None else [None] * len(checked)
    if len(per_mask) != len(checked):
        raise ValueError(f"masks must hold one entry per object ({len(checked)}), got {len(per_mask)}")
    shapes = {tuple(s.shape) for s in checked}
    if opts.flow == "tvl1" and len(shapes) > 1:
        raise ValueError(f"objects must share one seed shape, got {sorted(shapes)}")
    batched = opts.flow in _BATCHED and len(checked) >= 2 and len(shapes) == 1
    return _object_records(checked, per_mask, alpha, opts, batched)


def _object_records(
    checked: list[torch.Tensor],
    masks: list[torch.Tensor | None],
    alpha: float | Sequence[float],
    opts: SynthesisOptions,
    batched: bool,
) -> Iterator[list[PairGeometry]]:
    """:func:`iter_object_geometries`'s records for checked arguments."""
    if not batched:
        for s, m in zip(checked, masks, strict=True):
            yield pair_geometry(s, alpha, opts, m)
        return
    steps = pair_angles(alpha, checked[0].shape[0])
    corrs, seconds = _batched_tvl1(checked, opts) if opts.flow == "tvl1" else _by_angle(checked, steps, opts)
    n = len(steps)
    for o, (s, m) in enumerate(zip(checked, masks, strict=True)):
        yield _with_elevations(s, m, corrs[o * n : (o + 1) * n], seconds[o * n : (o + 1) * n], steps, opts)


def _pairs_per_call(seeds: torch.Tensor, alpha: float, opts: SynthesisOptions) -> int | None:
    """How many seed pairs of (V, C, H, W) ``seeds`` ``alpha`` apart one flow call takes: on
    the CPU with the row matcher (``"rows"``, ``"guided"``) those whose cost volumes fit in
    ``_tuning.FLOW_BATCH_CPU`` elements (at least one), else None (all at once)."""
    if seeds.device.type != "cpu" or opts.flow not in ("rows", "guided"):
        return None
    h, w = seeds.shape[-2:]
    kwargs = opts.flow_kwargs()
    f = 1
    if opts.flow == "guided":  # checked as guided_tvl1 checks it, before the flow runs
        f = prior_reduction(h, w, check_int(kwargs.get("prior_side", PRIOR_SIDE), "prior_side", minimum=1))
    depth = kwargs.get("depth")
    volume = volume_size(h // f, w // f, alpha, None if depth is None else float(depth) / f)  # type: ignore[arg-type]
    return max(1, _tuning.FLOW_BATCH_CPU // (2 * volume))  # both directions


def _by_angle(
    objects: list[torch.Tensor], steps: list[float], opts: SynthesisOptions
) -> tuple[list[Correspondence], list[float]]:
    """Every consecutive seed pair of every object (V, C, H, W), in order, one flow call per
    distinct angle between the seeds (the row matcher and the guided flow search the
    epipolar range of one α; the full circle has one α for all its pairs), split by
    :func:`_pairs_per_call`, and each pair's share of its call's seconds."""
    n = len(steps)
    corrs: list[Correspondence | None] = [None] * (n * len(objects))
    seconds = [0.0] * len(corrs)
    for step in sorted(set(steps)):
        pairs = [i for i in range(n) if steps[i] == step]
        firsts = torch.cat([s[pairs] for s in objects])
        nexts = torch.cat([s[[i + 1 for i in pairs]] for s in objects])
        per_call = _pairs_per_call(objects[0], step, opts) or len(firsts)
        at = [o * n + i for o in range(len(objects)) for i in pairs]
        for lo in range(0, len(firsts), per_call):
            t0 = time.perf_counter()
            batch = estimate_correspondence(
                firsts[lo : lo + per_call],
                nexts[lo : lo + per_call],
                method=opts.flow,
                threshold=opts.threshold,
                **opts.flow_kwargs(step),
            )
            share = (time.perf_counter() - t0) / len(batch)
            for j, corr in zip(at[lo : lo + per_call], batch, strict=True):
                corrs[j], seconds[j] = corr, share
    filled = [c for c in corrs if c is not None]
    assert len(filled) == len(corrs), "each pair has one angle, so every slot is filled"
    return filled, seconds


def _batched_tvl1(
    objects: list[torch.Tensor], opts: SynthesisOptions
) -> tuple[list[Correspondence], list[float]]:
    """Every consecutive seed pair of every object (V, C, H, W), in order, from one TV-L1
    call, and each pair's share of its seconds."""
    t0 = time.perf_counter()
    batch = estimate_correspondence(
        torch.cat([s[:-1] for s in objects]),
        torch.cat([s[1:] for s in objects]),
        method="tvl1",
        threshold=opts.threshold,
        **opts.flow_kwargs(),
    )
    corrs = list(batch)
    return corrs, [(time.perf_counter() - t0) / len(corrs)] * len(corrs)


def _with_elevations(
    seeds: torch.Tensor,
    masks: torch.Tensor | None,
    corrs: list[Correspondence],
    seconds: list[float],
    steps: list[float],
    opts: SynthesisOptions,
) -> list[PairGeometry]:
    """One object's records: each pair's correspondence with its elevation (measured for
    ``"auto"``), its seconds those of its flow plus the elevation fit."""
    fg = seed_foreground(seeds, masks, opts.background)
    out = []
    for n, corr in enumerate(corrs):
        t0 = time.perf_counter()
        elevation = opts.elevation
        if elevation == "auto":
            elevation = _auto_elevation(corr, steps[n], fg[n : n + 1], opts.center, n)
        out.append(PairGeometry(corr, float(elevation), seconds[n] + time.perf_counter() - t0))
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
        stacklevel=4,  # the caller of pair_geometry / object_geometries
    )
    return 0.0
