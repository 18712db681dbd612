"""Synthesized views as a sequence: how much nearer the real views they come than the seeds
do, which synthesized angle each real view is nearest to, and where the sequence jumps.

A seed pair α apart synthesizes the views at every degree from 0 to α (``eigview coil``'s
1° step); the real views between the seeds (COIL-20: every 5°, the seeds left out) are
compared with them as the recognizer compares views, unit-norm and by Euclidean
distance, in the full image space (no eigenspace, so what it shows is the synthesis's,
not the projection's). Per α, over every object, center and real view between the seeds:

- ``d seed``: the distance of the real view to the nearer seed, the mean;
- ``d synth``: its distance to the view synthesized at its own angle, the mean;
- ``gain``: ``1 − d synth / d seed``, the median: 1 for a perfect synthesis, 0 for views
  no nearer the real one than the seed already is, negative for worse;
- ``|shift|``: how far (degrees) the nearest synthesized view's angle lies from the real
  view's, the median: a pose estimate's error in a gallery of these views;
- ``pull``: how many degrees that nearest angle lies nearer to the nearer seed than the
  real view's own, the median (positive: pulled towards the seed; the midway view, with
  no nearer seed, left out; ``-`` where that is the only one);
- ``jump``: the largest step between consecutive synthesized views over the median step,
  the median over pairs: near 1 for a sequence that changes smoothly with the angle.

Run: ``python examples/diagnostics/diagnose_views.py [--root DIR] [--alphas 10 20 45]``
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
from collections.abc import Mapping, Sequence

import torch
from diagnostic_record import (
    add_centers_flag,
    add_objects_flag,
    add_record_flag,
    add_root_flag,
    check_record,
    coil_folder,
    command_line,
    table,
    text,
    write_record,
)

from torch_eigview import CoilFolder, SynthesisOptions, synthesize_views
from torch_eigview.nn import unit_rows
from torch_eigview.scale import threads

#: The options each table row synthesizes with: the defaults, and the size normalization
#: switched off (a jump that vanishes with it comes from the normalization's box).
VARIANTS: dict[str, dict[str, object]] = {
    "default": {},
    "size normalization: off": {"extent": False},
}


def pair_view_stats(
    seeds: torch.Tensor, real: torch.Tensor, alpha: float, step: float, options: SynthesisOptions
) -> tuple[list[tuple[float, float, float, float | None]], float]:
    """The figures of one seed pair.

    Args:
        seeds: (2, C, H, W) seed views at 0 and ``alpha``.
        real: (R, C, H, W) real views at ``step``, 2·``step``, …, R·``step`` from the first seed.
        alpha: angle between the seeds, degrees (a whole number).
        step: the real views' pose step, degrees.
        options: the synthesis's options.

    Returns:
        Per real view ``(d seed, d synth, shift, pull)`` (pull None midway between the
        seeds), and the pair's ``jump``.
    """
    n_synth = round(alpha) + 1
    thetas = torch.arange(n_synth, dtype=torch.float64)
    synth = unit_rows(synthesize_views(seeds, alpha, thetas, options).views.double())
    seed = unit_rows(seeds.double())
    views = unit_rows(real.double())
    distance = torch.cdist(views, synth)  # (R, T)
    to_seed = torch.cdist(views, seed).amin(dim=1)
    nearest = distance.argmin(dim=1).double()
    rows: list[tuple[float, float, float, float | None]] = []
    for i in range(views.shape[0]):
        angle = (i + 1) * step
        own = distance[i, round(angle)]
        shift = float(nearest[i]) - angle
        pull: float | None = None
        if abs(2 * angle - alpha) > 1e-9:
            near = 0.0 if 2 * angle < alpha else alpha
            pull = abs(angle - near) - abs(float(nearest[i]) - near)
        rows.append((float(to_seed[i]), float(own), shift, pull))
    steps = (synth[1:] - synth[:-1]).norm(dim=1)
    jump = float(steps.max() / steps.median().clamp_min(1e-12))
    return rows, jump


def view_gain_rows(
    folder: CoilFolder,
    objects: Sequence[int],
    centers: Sequence[float],
    alphas: Sequence[float],
    step: float = 5.0,
    variants: Mapping[str, Mapping[str, object]] = VARIANTS,
) -> list[list[object]]:
    """Per α and variant ``[alpha, options, views, d seed, d synth, gain, |shift|, pull, jump]``
    (see the module's docstring) over the seed pairs at each center; pull is None where
    every real view lies midway between the seeds."""
    if not objects or not centers or not alphas or not variants:
        raise ValueError(
            f"objects, centers, alphas and variants must each name at least one, got {list(objects)}, "
            f"{list(centers)}, {list(alphas)}, {list(variants)}"
        )
    if step <= 0 or abs(step - round(step)) > 1e-9:
        raise ValueError(
            f"step={step:g} must be a positive whole number of degrees (the views are synthesized every degree)"
        )
    for alpha in alphas:
        n_steps = round(alpha / step)
        if n_steps < 2 or abs(n_steps * step - alpha) > 1e-6:
            raise ValueError(
                f"alpha={alpha:g} must be a multiple of the poses' step {step:g}, at least two steps "
                "(a real view between the seeds)"
            )
    out: list[list[object]] = []
    for alpha in alphas:
        n_steps = round(alpha / step)
        for name, change in variants.items():
            opts = dataclasses.replace(SynthesisOptions(), **change)  # type: ignore[arg-type]
            rows: list[tuple[float, float, float, float | None]] = []
            jumps = []
            for obj in objects:
                for c in centers:
                    seeds = folder.images(obj, [c, c + alpha])
                    real = folder.images(obj, [c + i * step for i in range(1, n_steps)])
                    pair_rows, jump = pair_view_stats(seeds, real, alpha, step, opts)
                    rows += pair_rows
                    jumps.append(jump)
            pulls = [r[3] for r in rows if r[3] is not None]
            out.append(
                [
                    alpha,
                    name,
                    len(rows),
                    f"{statistics.mean(r[0] for r in rows):.3f}",
                    f"{statistics.mean(r[1] for r in rows):.3f}",
                    f"{statistics.median(1 - r[1] / max(r[0], 1e-12) for r in rows):+.2f}",
                    f"{statistics.median(abs(r[2]) for r in rows):.1f}",
                    f"{statistics.median(pulls):+.1f}" if pulls else None,
                    f"{statistics.median(jumps):.2f}",
                ]
            )
    return out


def main(argv: list[str] | None = None) -> list[list[object]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_root_flag(parser)
    add_objects_flag(parser)
    add_centers_flag(parser)
    parser.add_argument(
        "--alphas", type=float, nargs="+", default=[10.0, 20.0, 45.0], help="seed angles, degrees"
    )
    add_record_flag(parser, "diagnose_views")
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    folder = coil_folder(parser, args.root)
    objects = list(args.objects or folder.objects)
    try:  # an angle off the pose grid: one line naming it
        rows = view_gain_rows(folder, objects, args.centers, args.alphas)
    except ValueError as exc:
        parser.error(str(exc))
    tab = table(
        f"Real views between two seeds against the views synthesized at every degree, unit norm, in the "
        f"full image space ({len(objects)} objects × centers {', '.join(f'{c:g}' for c in args.centers)}): "
        "d seed the distance to the nearer seed, d synth to the view synthesized at its angle (means); "
        "gain = 1 − d synth / d seed, |shift| how far the nearest synthesized angle lies from the real "
        "one, pull how much nearer the seed it lies (degrees), jump the largest step between consecutive "
        "synthesized views over the median step (medians).",
        ["α", "options", "views", "d seed", "d synth", "gain", "|shift|", "pull", "jump"],
        rows,
    )
    print(text(tab))
    write_record(
        args.record,
        title="Diagnosis: the synthesized views as a sequence",
        command=command_line(__file__, argv),
        tables=[tab],
    )
    return rows


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
