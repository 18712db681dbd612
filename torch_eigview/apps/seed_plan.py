"""Where ``eigview fit``'s seed views lie and which angles each object's gallery holds.

:func:`seed_plan` turns ``--seeds``, ``--center`` and ``--synth`` into a :class:`SeedPlan`
(listed seeds: the gallery angles; ``--seeds M``: the full circle),
:func:`held_out_thetas` places the views that
calibrate rejection, and :func:`synth_record` is the gallery range the model file records.
Nothing here imports torch at import time (``eigview predict --onnx`` runs without it).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

__all__ = ["SeedPlan", "held_out_thetas", "reject_poses", "seed_plan", "synth_record"]

_TOL = 1e-6  # degrees: two azimuths this close are one pose


@dataclass(frozen=True)
class SeedPlan:
    """Where the seed views lie and which angles each object's gallery holds.

    Attributes:
        azimuths: the seed azimuths in degrees, in [0, 360), in the order of synthesis.
        first: the first seed's azimuth in (-180, 180], the origin of the gallery's angles.
        alpha: the angle between consecutive seeds (one number when equal, else Sec. 4.1's α_n).
        thetas: the gallery angles from the first seed (two or more listed seeds), or None
            for the full circle (every ``step`` round it).
        step: the synthesis step in degrees.
        steps: the signed angles from each listed seed to the next (empty for the circle).
    """

    azimuths: list[float]
    first: float
    alpha: float | list[float]
    thetas: list[float] | None
    step: float
    steps: list[float] = field(default_factory=list)


def seed_plan(
    seeds: list[float] | None,
    circle: int | None,
    center: float | None,
    synth: tuple[float, float, float] | None,
) -> SeedPlan:
    """The seed azimuths and gallery angles of ``--seeds`` (or ``--circle``), ``--center``
    and ``--synth`` (None: every degree from 20° before the first seed to 20° past the last,
    :func:`~torch_eigview.geometry.angles.around_seeds`, or every degree round the circle).

    Raises:
        ValueError: fewer than two listed seeds; listed seeds that repeat an azimuth or lie
            180 degrees apart; a bad ``--synth`` range; ``--center`` (None: not given) with
            listed seeds, where the first seed is the centre.
    """
    from torch_eigview.check import VIEW_LIMIT, check_limit  # imports torch: not on predict's path
    from torch_eigview.geometry.angles import angle_range, around_seeds, wrap_angle

    step = 1.0 if synth is None else synth[2]
    if synth is not None:
        angle_range(*synth, "--synth")  # names a bad range before any image is read
    if circle is not None:
        check_limit(circle, "--circle", "seed views round the circle", VIEW_LIMIT)
        center = 0.0 if center is None else center
        if circle < 4:
            # Each sector is synthesized from its first seed over [0, 360/M): Eq. 7 reaches
            # less than 90 degrees from a seed, so M = 3's 120-degree sectors cannot be.
            raise ValueError(
                f"--circle {circle} puts the seeds {360.0 / circle:g} degrees apart, but a view is synthesized "
                "less than 90 degrees from its sector's first seed (Eq. 7): give --circle 4 or more"
            )
        azimuths = [(center + k * 360.0 / circle) % 360.0 for k in range(circle)]
        return SeedPlan(azimuths, wrap_angle(center), 360.0 / circle, None, step)
    seeds = list(seeds or [])
    if center is not None:
        # Listed seeds place themselves: a --center beside them would be ignored, silently.
        raise ValueError(
            f"--center {center:g} goes with --circle (the first of M seeds); with --seeds the first listed "
            f"azimuth ({' '.join(f'{a:g}' for a in seeds)}) is the centre: drop --center or list the seeds from it"
        )
    if len(seeds) < 2:
        raise ValueError(
            f"--seeds {' '.join(f'{a:g}' for a in seeds)} needs two or more azimuths to synthesize from "
            "(--circle M for M seed views round the whole circle)"
        )
    steps = [wrap_angle(b - a) for a, b in itertools.pairwise(seeds)]
    if any(abs(s) < _TOL for s in steps):
        raise ValueError(f"--seeds {' '.join(f'{a:g}' for a in seeds)} repeats an azimuth")
    if any(abs(abs(s) - 180.0) < _TOL for s in steps):
        raise ValueError(
            f"--seeds {' '.join(f'{a:g}' for a in seeds)} puts consecutive seeds 180 degrees apart, a multiple "
            "of 180 where Eq. 7's sin(alpha) is 0: list seeds less than 180 degrees apart"
        )
    equal = all(abs(s - steps[0]) < _TOL for s in steps)
    if synth is None:
        thetas = angle_range(*around_seeds(steps), "--synth")
    else:
        # Each seed past the second extends the range on its side by its step (as CoilExperiment).
        extra = (len(steps) - 1) * steps[0] if equal else sum(steps[1:])
        thetas = angle_range(synth[0] + min(extra, 0.0), synth[1] + max(extra, 0.0), step, "--synth")
    alpha: float | list[float] = steps[0] if equal else steps
    return SeedPlan([a % 360.0 for a in seeds], wrap_angle(seeds[0]), alpha, thetas, step, steps)


def synth_record(synth: list[float] | None, plan: SeedPlan) -> list[float]:
    """The model's record of the gallery range: ``--synth`` as given, else the default's
    (start, stop, step) from the first seed (every ``step`` round the circle)."""
    if synth is not None:
        return [float(v) for v in synth]
    if plan.thetas is None:
        return [0.0, 360.0 - plan.step, plan.step]
    return [plan.thetas[0], plan.thetas[-1], plan.step]


def reject_poses(plan: SeedPlan, given: tuple[float, float, float] | None) -> tuple[float, float, float]:
    """``--reject-poses`` as given, else every 2.5° from 45° before the first listed seed to
    45° past the last (25° past the default gallery on both sides); for the full circle,
    where the held-out views are the midpoints between gallery views, those midpoints'
    range."""
    from torch_eigview.geometry.angles import held_out_range

    if plan.thetas is None:
        return (plan.step / 2, 360.0 - plan.step / 2, plan.step)
    return given or held_out_range(plan.steps)


def held_out_thetas(plan: SeedPlan, poses: tuple[float, float, float] | None) -> list[float]:
    """Angles (from the first seed) of the views that calibrate rejection, none a gallery angle.

    Listed seeds: ``angle_range(*poses)`` less the gallery's angles, round the circle. The
    full circle: the midpoints between consecutive gallery angles all round (``poses``
    unused; only their number matters, the views come from ``fit_command``'s gallery).
    None: no rejection, no views.
    """
    from torch_eigview.geometry.angles import angle_range, off_gallery

    if poses is None:
        return []
    if plan.thetas is None:
        return [t + plan.step / 2 for t in angle_range(0.0, 360.0 - plan.step, plan.step, "--synth")]
    return off_gallery(poses, plan.thetas, "--reject-poses")
