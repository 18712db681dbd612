"""Where the COIL experiment breaks down: the synthesis error per stage, and the pose error.

``python examples/diagnostics/diagnose.py TABLE... [--root DIR]`` prints, for the tables
asked, and writes each to its record (``results/diagnose_<table>.json``):

- ``synthesis``: the error of synthesized views against the real COIL views at the
  synthesized angles that exist (every 5°, the seeds' own poses left out), per center
  and for the full circle, as the mean absolute intensity difference over the pixels
  both seeds see and over the rest of the foreground (real or synthesized), for the
  default options and for each stage ablated or swapped (:data:`ABLATIONS`);
- ``pose``: where the full circle's pose error comes from (``--pose-seeds`` M, the
  ``eigview coil`` defaults otherwise): the mean and median error of the correctly
  recognized views, over all objects and without the nearly rotationally symmetric ones
  (:func:`symmetric_objects`), then per object and per position within a sector (its
  angle from the sector's first seed) with the median signed error (predicted − true:
  negative where a view is taken for one nearer the sector's first seed).

The other diagnoses are scripts of their own beside this one: the correspondences against
the chained real motion (``diagnose_flow.py``), the synthesized views as a sequence
(``diagnose_views.py``) and the synthesis with the chained real motion
(``diagnose_chained.py``). Every figure comes from the same code as ``eigview coil``; the
same settings hold for every object and pose.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from diagnostic_record import (
    RESULTS,
    add_centers_flag,
    add_objects_flag,
    add_root_flag,
    check_record,
    coil_folder,
    command_line,
    table,
    text,
    write_record,
)

from torch_eigview import CoilFolder, NovelViewWarp, SynthesisOptions
from torch_eigview.evaluation import CoilExperiment, circle_layout
from torch_eigview.scale import threads
from torch_eigview.synthesis import pair_geometry
from torch_eigview.warp import foreground_mask, normalize_extent

#: The tables :func:`main` prints.
TABLES = ("synthesis", "pose")
#: A view whose object's bounding box spans at least this fraction of the frame counts as
#: size-normalized (``SynthesisOptions(extent="auto")``'s rule).
FILLED_FRAME = 0.95

# Each stage of the synthesis swapped for an alternative (or switched off), one at a time.
ABLATIONS: dict[str, dict[str, object]] = {
    "default": {},
    "correspondence: ilk flow": {"flow": "ilk"},
    "correspondence: tvl1 alone": {"flow": "tvl1"},
    "correspondence: guided, TV-L1 5x10 iterations": {"flow_options": {"num_warp": 5, "num_iter": 10}},
    "tilt: elevation 0": {"elevation": 0.0},
    "occlusion: max_stretch inf": {"max_stretch": float("inf")},
    "size normalization: off": {"extent": False},
    "blend: nearest seed": {"blend": "nearest"},
    "blend: silhouette-aware": {"silhouette": True},
}


def angle_range(start: float, stop: float, step: float) -> list[float]:
    """``start, start + step, …, stop`` (inclusive), as the experiments list angles."""
    n = int((stop - start) / step + 1e-9) + 1
    return [start + i * step for i in range(n)]


def wrap_degrees(angles: torch.Tensor) -> torch.Tensor:
    """Angles wrapped to (−180, 180]."""
    return 180 - torch.remainder(180 - angles, 360)


def size_normalized(extent: bool | str, masks: torch.Tensor) -> bool:
    """Whether the synthesis size-normalizes views from seeds with (V, H, W) foreground
    ``masks``: ``extent`` as it is, or for ``"auto"`` when every seed's object box fills
    the frame (its longer side by :func:`~torch_eigview.warp.normalize_extent`'s rule)."""
    if extent != "auto":
        return bool(extent)
    h, w = masks.shape[-2:]
    fills = []
    for mask in masks:
        rows, cols = mask.any(dim=1).nonzero(), mask.any(dim=0).nonzero()
        if rows.numel() == 0:
            return False
        fill = max(float(cols[-1] - cols[0]) / max(w - 1, 1), float(rows[-1] - rows[0]) / max(h - 1, 1))
        fills.append(fill)
    return min(fills) >= FILLED_FRAME


def _pair_error(
    seeds: torch.Tensor, alpha: float, thetas: list[float], real: torch.Tensor, opts: SynthesisOptions
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per view the summed absolute error and pixel count over (both seen, the rest): (T, 2) each.

    The synthesis of :func:`~torch_eigview.synthesis.synthesize_views` for two seeds, with
    the both-seen mask (``WarpMaps.hit`` of both seeds) carried through the size
    normalization as one more channel.
    """
    geo = pair_geometry(seeds, alpha, opts)[0]
    warp = NovelViewWarp(
        alpha, opts.center, max_stretch=opts.max_stretch, elevation=geo.elevation, blend=opts.blend
    )
    maps = warp.maps(geo.correspondence, thetas)
    pair = seeds[:, None]
    fg = foreground_mask(pair, opts.background)
    masks = fg if opts.silhouette else None
    channels = [pair, fg.to(seeds.dtype)[:, :, None], torch.zeros_like(pair[:, :, :1])]
    warped = warp.apply_maps(maps, torch.cat(channels, dim=2), masks)[0]
    both = (maps.hit[0] & maps.hit[1])[0].to(seeds.dtype)[:, None]
    warped[:, -1:] = both
    if size_normalized(opts.extent, foreground_mask(seeds, opts.background)):
        warped = normalize_extent(warped, warped[:, -2] > 0.5)
    views, both_seen = warped[:, :-2], warped[:, -1] > 0.5
    err = (views - real).abs().mean(dim=1)
    support = foreground_mask(views, opts.background) | foreground_mask(real, opts.background)
    rest = support & ~both_seen
    sums = torch.stack([(err * both_seen).sum(dim=(1, 2)), (err * rest).sum(dim=(1, 2))], dim=1)
    counts = torch.stack([both_seen.sum(dim=(1, 2)), rest.sum(dim=(1, 2))], dim=1)
    return sums, counts.to(sums.dtype)


def synthesis_error(
    folder: CoilFolder,
    objects: Sequence[int],
    seed_poses: Sequence[float],
    opts: SynthesisOptions,
    targets: Sequence[float],
) -> tuple[float, float]:
    """Mean absolute error (both seen, rest) of the views that pairs of consecutive
    ``seed_poses`` (closed into a loop when they go all round) synthesize at the real
    poses ``targets`` relative to each pair's first seed."""
    loop = len(seed_poses) > 2
    pairs = [
        (seed_poses[k], seed_poses[(k + 1) % len(seed_poses)]) for k in range(len(seed_poses) - (not loop))
    ]
    total = torch.zeros(2, dtype=torch.float64)
    count = torch.zeros(2, dtype=torch.float64)
    for obj in objects:
        for first, second in pairs:
            alpha = float(wrap_degrees(torch.tensor(second - first)))
            seeds = folder.images(obj, [first, second])
            real = folder.images(obj, [first + t for t in targets])
            sums, counts = _pair_error(seeds, alpha, list(targets), real, opts)
            total += sums.sum(dim=0).double()
            count += counts.sum(dim=0).double()
    mean = total / count.clamp_min(1)
    return float(mean[0]), float(mean[1])


@dataclass(frozen=True)
class PoseRecord:
    """One correctly recognized test view: its object, true pose and signed pose error
    (predicted − true, wrapped to (−180, 180], degrees)."""

    obj: int
    truth: float
    error: float


def pose_records(
    folder: CoilFolder, objects: list[int], m: int, k: int, interpolate: bool = False
) -> tuple[list[PoseRecord], float]:
    """The full circle with M seeds (``eigview coil --seeds M`` otherwise at its defaults):
    a :class:`PoseRecord` per correctly recognized test view, and α = 360 / M."""
    exp = CoilExperiment(seeds=m, components=k, objects=objects, interpolate_pose=interpolate)
    result = exp.run(folder)
    layout = exp.circle(folder, objects)
    truth = torch.tensor(layout.tests, dtype=torch.float64)
    records = []
    for obj in objects:
        pred = result.recognizer.predict(folder.images(obj, layout.tests), interpolate_pose=interpolate)
        error = wrap_degrees(pred.poses.double() - truth)
        for t, e, ok in zip(layout.tests, error.tolist(), (pred.labels == obj).tolist(), strict=True):
            if ok:
                records.append(PoseRecord(obj, t, e))
    return records, layout.alpha


def symmetric_objects(folder: CoilFolder, objects: Sequence[int], below: float) -> list[int]:
    """The objects whose real views change less than ``below`` per pose step: the mean
    distance between consecutive poses' unit-norm views (cups, tubs: no defined pose)."""
    out = []
    for obj in objects:
        views = folder.images(obj, folder.poses(obj)).flatten(1).double()
        views = views / views.norm(dim=1, keepdim=True).clamp_min(1e-12)
        if float((views - views.roll(1, 0)).norm(dim=1).mean()) < below:
            out.append(obj)
    return out


def _errors_row(name: str, errors: Sequence[float]) -> list[Any]:
    """``[name, n, mean |e|, median |e|, median signed e]`` (NaN when there are none)."""
    if not errors:
        return [name, 0, float("nan"), float("nan"), float("nan")]
    absolute = [abs(e) for e in errors]
    return [
        name,
        len(errors),
        statistics.mean(absolute),
        statistics.median(absolute),
        statistics.median(errors),
    ]


def pose_summary(records: Sequence[PoseRecord], alpha: float, symmetric: Sequence[int]) -> list[list[Any]]:
    """The pose-error table of :func:`pose_records`' records: all views, those of the objects
    not in ``symmetric``, per object and per position within a sector.

    Example:
        >>> rows = [PoseRecord(1, 10.0, -4.0), PoseRecord(1, 35.0, 2.0), PoseRecord(2, 10.0, 30.0)]
        >>> pose_summary(rows, 45.0, [2])[0]
        ['all', 3, 12.0, 4.0, 2.0]
    """
    rows = [
        _errors_row("all", [r.error for r in records]),
        _errors_row(
            f"w/o {','.join(map(str, symmetric)) or '-'}",
            [r.error for r in records if r.obj not in symmetric],
        ),
    ]
    for obj in sorted({r.obj for r in records}):
        rows.append(_errors_row(f"object {obj}", [r.error for r in records if r.obj == obj]))
    for position in sorted({round(r.truth % alpha, 6) for r in records}):
        errors = [r.error for r in records if abs(r.truth % alpha - position) < 1e-6]
        rows.append(_errors_row(f"sector +{position:g}", errors))
    return rows


def synthesis_rows(
    folder: CoilFolder, objects: list[int], centers: list[float], alpha: float, m: int
) -> list[list[Any]]:
    """Synthesis error per ablation, ``both seen / rest`` per center (seeds α apart) and for
    the full circle (M seeds)."""
    pair_targets = [t for t in angle_range(-20.0, 20.0, 5.0) if t not in (0.0, alpha)]
    circle = circle_layout(folder.poses(objects[0]), 0.0, m, "nvs")
    circle_targets = angle_range(5.0, circle.alpha - 5.0, 5.0)
    rows = []
    for name, change in ABLATIONS.items():
        opts = dataclasses.replace(SynthesisOptions(), **change)  # type: ignore[arg-type]
        cells = [synthesis_error(folder, objects, [c, c + alpha], opts, pair_targets) for c in centers]
        cells.append(synthesis_error(folder, objects, circle.seeds, opts, circle_targets))
        rows.append([name, *(f"{a:.4f} / {b:.4f}" for a, b in cells)])
        print(f"{name:46s}" + "".join(f"{a:8.4f}/{b:6.4f}" for a, b in cells), flush=True)
    return rows


def main(argv: list[str] | None = None) -> dict[str, dict[str, Any]]:
    """Entry point: prints the tables named on the command line and writes their records."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("tables", nargs="+", choices=TABLES)
    add_root_flag(p)
    add_objects_flag(p)
    add_centers_flag(p)
    p.add_argument("--alpha", type=float, default=10.0, help="the synthesis table's seed angle per center")
    p.add_argument("--seeds", type=int, default=4, help="M of the synthesis table's full circle (>= 3)")
    p.add_argument("--components", type=int, default=15, help="k of the pose table")
    p.add_argument("--pose-seeds", type=int, default=8, help="M of the pose table")
    p.add_argument(
        "--symmetric-below",
        type=float,
        default=0.1,
        help="the pose table leaves out objects whose unit-norm views change less than this per pose step",
    )
    p.add_argument("--interpolate", action="store_true", help="the pose table scores --pose interpolate")
    p.add_argument(
        "--records",
        default=str(RESULTS),
        help="the folder of the records, diagnose_<table>.json (default examples/diagnostics/results; '' for none)",
    )
    args = p.parse_args(argv)
    paths = {t: str(Path(args.records) / f"diagnose_{t}.json") if args.records else "" for t in args.tables}
    for path in paths.values():
        check_record(p, path)
    folder = coil_folder(p, args.root)
    objects = list(args.objects or folder.objects)
    out = {}
    try:  # a bad object list, angle or M: one line naming it, not a traceback
        for name in args.tables:
            out[name] = _table(name, folder, objects, args)
            print(text(out[name]))
            write_record(
                paths[name],
                title=TITLES[name],
                command=command_line(__file__, argv),
                tables=[out[name]],
            )
    except ValueError as exc:
        p.error(str(exc))
    return out


TITLES = {
    "synthesis": "Diagnosis: synthesized against real views, per stage of the synthesis",
    "pose": "Diagnosis: where the full circle's pose error comes from",
}


def _table(name: str, folder: CoilFolder, objects: list[int], args: argparse.Namespace) -> dict[str, Any]:
    """One table of :func:`main`'s, from its parsed arguments."""
    if name == "pose":
        records, alpha = pose_records(folder, objects, args.pose_seeds, args.components, args.interpolate)
        symmetric = symmetric_objects(folder, objects, args.symmetric_below)
        return table(
            f"Pose error (degrees) of the correctly recognized views, full circle M = {args.pose_seeds}, "
            f"k = {args.components}, the {'interpolated' if args.interpolate else 'nearest view'}'s pose "
            f"({len(objects)} objects): all, without the nearly symmetric objects, per object and per "
            "position within a sector (degrees from its first seed); signed: the median of predicted − true.",
            ["views", "n", "mean", "median", "signed"],
            pose_summary(records, alpha, symmetric),
        )
    if args.seeds < 3:
        raise ValueError(f"--seeds={args.seeds} must be >= 3 (seeds 180 degrees apart leave Eq. 7 singular)")
    rows = synthesis_rows(folder, objects, args.centers, args.alpha, args.seeds)
    return table(
        f"Mean |synthesized − real| over the pixels both seeds see / the rest of the foreground, at the real "
        f"poses every 5° between and beyond the seeds ({len(objects)} objects): per center, seeds "
        f"{args.alpha:g}° apart, −20°..20°; and the full circle, M = {args.seeds}. One stage of the "
        "synthesis changed per row.",
        ["options", *(f"center {c:g}" for c in args.centers), f"M = {args.seeds}"],
        rows,
    )


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
