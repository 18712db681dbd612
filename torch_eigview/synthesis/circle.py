"""The full circle: Sec. 4.1's chain of seed pairs closed on itself.

M seed views evenly spaced over 360° (α = 360°/M); every consecutive pair, the last seed
with the first included, synthesizes its own sector [0, α) from its first seed, so the
gallery goes once round the turntable and every seed's own view comes from the pair it
starts (:func:`~torch_eigview.synthesis.pair_of`'s rule). With an ``overlap`` each pair
also extrapolates past both of its seeds, so near every seed the gallery holds the views
of both pairs that meet there, each warping that seed by its own correspondence; each
degree of overlap adds two views per pair, so it is off by default.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.check import check_number, check_positive
from torch_eigview.geometry.angles import angle_range
from torch_eigview.synthesis.options import SynthesisOptions
from torch_eigview.synthesis.seed_pairs import PairGeometry
from torch_eigview.synthesis.views import SynthesizedViews, synthesize_views

__all__ = ["Circle", "check_overlap", "circle_thetas", "synthesize_circle"]

_TOL = 1e-6


@dataclass(frozen=True)
class Circle:
    """The full circle as a gallery: what :class:`~torch_eigview.method.FewViewEigenspace`
    synthesizes from M seed views evenly spaced round the turntable (``synth=Circle()``,
    or ``synth="circle"`` for the defaults).

    Attributes:
        step: degrees between synthesized views, > 0 (1 by default: the paper's step).
        overlap: degrees each seed pair also extrapolates past its seeds
            (:func:`synthesize_circle`), 0 for none.
    """

    step: float = 1.0
    overlap: float = 0.0

    def __post_init__(self) -> None:
        check_positive(self.step, "Circle.step")
        check_positive(self.overlap, "Circle.overlap", allow_zero=True)


def check_overlap(m: int, overlap: object, name: str = "overlap") -> float:
    """``overlap`` as a float, or a ValueError naming ``name``: it must lie in [0, α/2]
    (α = 360/M) and, above 0, keep α + overlap below 90 degrees (Eq. 7 holds within a
    quarter turn of a pair's first seed)."""
    value = check_number(overlap, name)
    alpha = 360.0 / m
    if not (0 <= value <= alpha / 2 and (value == 0 or alpha + value < 90)):
        raise ValueError(
            f"{name}={value:g} must be in [0, alpha/2 = {alpha / 2:g}] degrees and, above 0, below "
            f"90 - alpha = {90 - alpha:g} (M={m}: Eq. 7 holds within a quarter turn of a pair's first seed)"
        )
    return value


def circle_thetas(m: int, step: float, overlap: float = 0.0) -> list[float]:
    """The angles each of the M seed pairs synthesizes, degrees from its first seed: every
    ``step`` over its sector [0, 360/M), and ``overlap`` degrees past both of its seeds.

    Example:
        >>> circle_thetas(4, 30.0), circle_thetas(6, 20.0, overlap=20.0)
        ([0.0, 30.0, 60.0], [-20.0, 0.0, 20.0, 40.0, 80.0])
    """
    alpha = 360.0 / m
    overlap = check_overlap(m, overlap)
    thetas = [t for t in angle_range(0.0, alpha, step, "Circle.step") if t < alpha - _TOL]
    n_out = math.floor(overlap / step + _TOL)
    return (
        [-step * i for i in range(n_out, 0, -1)] + thetas + [alpha + step * i for i in range(n_out + 1)][1:]
    )


def synthesize_circle(
    seeds: torch.Tensor,
    step: float,
    options: SynthesisOptions | None = None,
    masks: torch.Tensor | None = None,
    overlap: float = 0.0,
    geometry: Sequence[PairGeometry] | None = None,
) -> SynthesizedViews:
    """One object's views all round from its M evenly spaced seed views.

    Pair k (seeds k and k + 1 mod M) synthesizes θ = 0, step, … < α = 360/M from seed k;
    with an ``overlap`` it also extrapolates ``overlap`` degrees past each of its seeds
    (θ = −overlap … < 0 and α < θ <= α + overlap, on the grid of ``step``), so near every
    seed the gallery holds the views of both pairs that meet there.

    Args:
        seeds: (M, C, H, W) seed views at 0, α, …, (M − 1)·α from the first, M >= 3.
        step: angle between synthesized views in degrees.
        options: the synthesis options.
        masks: optional (M, H, W) bool seed masks, in place of the brightness threshold.
        overlap: degrees each pair extrapolates past its seeds, in [0, α/2] and below
            90 − α (Eq. 7 holds within a quarter turn of a pair's first seed).
        geometry: the M pairs' correspondences (pair k: seeds k and k + 1 mod M), if
            already computed (:func:`~torch_eigview.synthesis.pair_geometry` of each pair);
            None measures them.

    Returns:
        :class:`~torch_eigview.synthesis.SynthesizedViews`: (M·T, C, H, W) views, their
        angles from the first seed in [0, 360), one elevation per pair, the times and
        each view's pair k.

    Raises:
        ValueError: fewer than 3 seeds, ``overlap`` outside [0, α/2] or not below 90 − α,
            or a ``geometry`` without one record per pair.
    """
    m = seeds.shape[0]
    if m < 3:  # M = 2 puts the seeds 180 degrees apart, where Eq. 7's sin(alpha) is 0
        raise ValueError(f"seeds must hold M >= 3 views evenly spaced round the circle, got M={m}")
    if geometry is not None and len(geometry) != m:
        raise ValueError(f"geometry must hold one record per seed pair (M = {m}), got {len(geometry)}")
    alpha = 360.0 / m
    thetas = circle_thetas(m, step, overlap)
    views, elevations, seconds = [], [], {"correspondence": 0.0, "synthesis": 0.0}
    for k in range(m):
        pair = [k, (k + 1) % m]
        out = synthesize_views(
            seeds[pair],
            alpha,
            thetas,
            options,
            geometry=None if geometry is None else [geometry[k]],
            masks=None if masks is None else masks[pair],
        )
        views.append(out.views)
        elevations += out.elevations
        for key, value in out.seconds.items():
            seconds[key] += value
    angles = torch.tensor([(k * alpha + t) % 360 for k in range(m) for t in thetas], dtype=torch.float64)
    pairs = torch.arange(m).repeat_interleave(len(thetas))
    return SynthesizedViews(torch.cat(views), angles, elevations, seconds, pairs)
