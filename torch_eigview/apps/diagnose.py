"""Where the COIL experiment breaks down: recognition tables, misses and synthesis error.

``python -m torch_eigview.apps.diagnose --root DIR TABLE...`` prints, for the tables asked:

- ``centers``: accuracy of ``nvs``, ``dense`` and ``sparse`` per center (two seed views
  α apart, the default ranges), then each ``nvs`` miss as object@pose, split into those
  inside the synthesized range and those beyond it;
- ``circle``: the full circle per M (``nvs``, ``sparse`` with the M seeds, ``dense`` with
  about 2M real views), with the mean and median pose error of recognized views;
- ``synthesis``: the error of synthesized views against the real COIL views at the
  synthesized angles that exist (every 5°, the seeds' own poses left out), per center
  and for the full circle, as the mean absolute intensity difference over the pixels
  both seeds see and over the rest of the foreground (real or synthesized), for the
  default options and for each stage ablated or swapped (:data:`ABLATIONS`);
- ``correspondence``: each flow's seed-pair disparities against the motion chained
  through the real views between the seeds (:mod:`torch_eigview.apps.diagnose_flow`);
- ``chained``: ``nvs`` per center and per M with that chained real motion as every seed
  pair's correspondence, beside the default flow and ``dense``: what better
  correspondences alone would change (:mod:`torch_eigview.apps.diagnose_chained`);
- ``views``: the synthesized views as a sequence against the real views between the
  seeds: how much nearer than the seeds they come, the pull of a real view's nearest
  synthesized angle towards the seeds, and jumps (:mod:`torch_eigview.apps.diagnose_views`);
- ``pose``: where the full circle's pose error comes from (``--pose-seeds`` M, the
  ``eigview coil`` defaults otherwise): the mean and median error of the correctly
  recognized views, over all objects and without the nearly rotationally symmetric ones
  (:func:`symmetric_objects`), then per object and per position within a sector (its
  angle from the sector's first seed) with the median signed error (predicted − true:
  negative where a view is taken for one nearer the sector's first seed).

Every figure comes from the same code as ``eigview coil``; the same settings hold for
every object and pose.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.apps.diagnose_chained import chained_table
from torch_eigview.apps.diagnose_flow import correspondence_table
from torch_eigview.apps.diagnose_views import view_gain_table
from torch_eigview.datasets.coil import CoilFolder, parse_object_spec
from torch_eigview.evaluation.circle import circle_layout
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.geometry.angles import angle_range, wrap_degrees
from torch_eigview.synthesis import SynthesisOptions, pair_geometry
from torch_eigview.warp.normalize import foreground_mask, normalize_extent, resolve_extent
from torch_eigview.warp.novel_view import NovelViewWarp

__all__ = [
    "ABLATIONS",
    "TABLES",
    "PoseRecord",
    "center_table",
    "circle_table",
    "main",
    "pose_records",
    "pose_summary",
    "symmetric_objects",
    "synthesis_error",
]

#: The tables :func:`main` prints.
TABLES = ("centers", "circle", "synthesis", "pose", "correspondence", "views", "chained")

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
    if resolve_extent(opts.extent, foreground_mask(seeds, opts.background)):
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


def _errors_line(name: str, errors: Sequence[float]) -> str:
    """``name  n  mean|e|  median|e|  median signed e`` (NaN when there are none)."""
    if not errors:
        return f"{name:>16} {0:5d} {'nan':>7} {'nan':>7} {'nan':>7}"
    absolute = [abs(e) for e in errors]
    return (
        f"{name:>16} {len(errors):5d} {statistics.mean(absolute):7.2f} "
        f"{statistics.median(absolute):7.2f} {statistics.median(errors):+7.2f}"
    )


def pose_summary(records: Sequence[PoseRecord], alpha: float, symmetric: Sequence[int]) -> str:
    """The pose-error table of :func:`pose_records`' records.

    Example:
        >>> rows = [PoseRecord(1, 10.0, -4.0), PoseRecord(1, 35.0, 2.0), PoseRecord(2, 10.0, 30.0)]
        >>> print(pose_summary(rows, 45.0, [2]).splitlines()[2])
                     all     3   12.00    4.00   +2.00
    """
    lines = [
        "pose error of correctly recognized views, degrees (signed: predicted - true)",
        f"{'':>16} {'n':>5} {'mean':>7} {'median':>7} {'signed':>7}",
        _errors_line("all", [r.error for r in records]),
        _errors_line(
            f"w/o {','.join(map(str, symmetric)) or '-'}",
            [r.error for r in records if r.obj not in symmetric],
        ),
    ]
    for obj in sorted({r.obj for r in records}):
        lines.append(_errors_line(f"object {obj}", [r.error for r in records if r.obj == obj]))
    for position in sorted({round(r.truth % alpha, 6) for r in records}):
        errors = [r.error for r in records if abs(r.truth % alpha - position) < 1e-6]
        lines.append(_errors_line(f"sector +{position:g}", errors))
    return "\n".join(lines)


def center_table(folder: CoilFolder, objects: list[int], centers: list[float], alpha: float, k: int) -> str:
    """Accuracy per center and method, and the ``nvs`` misses inside and beyond its range."""
    lines = [f"{'center':>7} {'nvs':>7} {'dense':>7} {'sparse':>7}  nvs misses inside / beyond synth"]
    for c in centers:
        base = CoilExperiment(alpha=alpha, center=c, components=k, objects=objects)
        accs, nvs = [], None
        for method in ("nvs", "dense", "sparse"):
            result = dataclasses.replace(base, method=method).run(folder)
            accs.append(result.accuracy)
            nvs = nvs or result
        assert nvs is not None
        start, stop = base.synth_range()
        inside: list[str] = []
        beyond: list[str] = []
        for a in angle_range(base.test[0], base.test[1], 5.0, "test"):
            for obj in objects:
                pred = nvs.recognizer.predict(folder.images(obj, [c + a]))
                if int(pred.labels[0]) != obj:
                    (inside if start <= a <= stop else beyond).append(f"{obj}@{a:+g}")
        lines.append(
            f"{c:7g} {accs[0]:7.2f} {accs[1]:7.2f} {accs[2]:7.2f}  "
            f"{len(inside)} [{' '.join(inside)}] / {len(beyond)} [{' '.join(beyond)}]"
        )
    return "\n".join(lines)


def circle_table(folder: CoilFolder, objects: list[int], ms: list[int], k: int, step: float) -> str:
    """The full circle per M: accuracy of nvs, sparse (M) and dense (~2M), nvs pose error."""
    lines = [
        f"{'M':>3} {'nvs':>7} {'sparse':>7} {'dense':>7} {'n_dense':>7} {'pose mean':>9} {'median':>7} {'s':>6}"
    ]
    for m in ms:
        base = CoilExperiment(
            seeds=m, components=k, objects=objects, synth=(0.0, 0.0, step), interpolate_pose=True
        )
        runs = {
            method: dataclasses.replace(base, method=method).run(folder)
            for method in ("nvs", "sparse", "dense")
        }
        nvs = runs["nvs"]
        lines.append(
            f"{m:3d} {nvs.accuracy:7.2f} {runs['sparse'].accuracy:7.2f} {runs['dense'].accuracy:7.2f} "
            f"{runs['dense'].n_train_views // len(objects):7d} {nvs.pose_mae_deg:9.2f} "
            f"{nvs.pose_median_deg:7.2f} {nvs.seconds['total']:6.1f}"
        )
    return "\n".join(lines)


def synthesis_table(
    folder: CoilFolder, objects: list[int], centers: list[float], alpha: float, m: int
) -> str:
    """Synthesis error per ablation: per center (α) and for the full circle (M)."""
    pair_targets = [t for t in angle_range(-20.0, 20.0, 5.0, "synth") if t not in (0.0, alpha)]
    circle = circle_layout(folder.poses(objects[0]), 0.0, m, "nvs")
    circle_targets = [t for t in angle_range(5.0, circle.alpha - 5.0, 5.0, "synth")]
    heads = [f"c{c:g}" for c in centers] + [f"M{m}"]
    lines = [
        "mean |synthesized - real| over pixels both seeds see / the rest of the foreground",
        f"{'options':38}" + "".join(f"{h:>14}" for h in heads),
    ]
    for name, change in ABLATIONS.items():
        opts = dataclasses.replace(SynthesisOptions(), **change)  # type: ignore[arg-type]
        cells = [synthesis_error(folder, objects, [c, c + alpha], opts, pair_targets) for c in centers]
        cells.append(synthesis_error(folder, objects, circle.seeds, opts, circle_targets))
        lines.append(f"{name:38}" + "".join(f"{a:7.4f}/{b:6.4f}" for a, b in cells))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: prints the tables named on the command line."""
    p = argparse.ArgumentParser(
        prog="python -m torch_eigview.apps.diagnose", description=__doc__.splitlines()[0]
    )
    p.add_argument("tables", nargs="+", choices=TABLES)
    p.add_argument("--root", required=True, help="COIL folder")
    p.add_argument("--objects", default=None, help="e.g. 1-20 (default: all)")
    p.add_argument("--centers", type=float, nargs="+", default=[0.0, 90.0, 180.0, 270.0])
    p.add_argument("--alpha", type=float, default=10.0)
    p.add_argument("--components", type=int, default=15, help="k of the per-center table")
    p.add_argument("--circle-components", type=int, default=20, help="k of the full circle")
    p.add_argument("--seeds", type=int, nargs="+", default=[4, 6, 8, 12], help="M of the full circle")
    p.add_argument("--step", type=float, default=5.0, help="the full circle's synthesized step, degrees")
    p.add_argument("--pose-seeds", type=int, default=8, help="M of the pose table")
    p.add_argument(
        "--symmetric-below",
        type=float,
        default=0.1,
        help="the pose table leaves out objects whose unit-norm views change less than this per pose step",
    )
    p.add_argument("--interpolate", action="store_true", help="the pose table scores --pose interpolate")
    p.add_argument(
        "--flow-alphas",
        type=float,
        nargs="+",
        default=[10.0, 45.0],
        help="seed angles of the correspondence table",
    )
    p.add_argument(
        "--view-alphas",
        type=float,
        nargs="+",
        default=[10.0, 20.0, 45.0],
        help="seed angles of the views table",
    )
    args = p.parse_args(argv)
    try:  # a bad folder, object list or angle: one line naming it, not a traceback
        folder = CoilFolder(args.root)
        objects = folder.objects if args.objects is None else parse_object_spec(args.objects)
        for table in args.tables:
            print(_table(table, folder, objects, args))
    except ValueError as exc:
        p.error(str(exc))
    return 0


def _table(table: str, folder: CoilFolder, objects: list[int], args: argparse.Namespace) -> str:
    """One table of :func:`main`'s, from its parsed arguments."""
    if table == "centers":
        return center_table(folder, objects, args.centers, args.alpha, args.components)
    if table == "circle":
        return circle_table(folder, objects, args.seeds, args.circle_components, args.step)
    if table == "correspondence":
        return correspondence_table(folder, objects, args.centers, args.flow_alphas)
    if table == "views":
        return view_gain_table(folder, objects, args.centers, args.view_alphas)
    if table == "chained":
        return chained_table(
            folder,
            objects,
            args.centers,
            args.alpha,
            args.seeds,
            args.components,
            args.circle_components,
            args.step,
        )
    if table == "pose":
        records, alpha = pose_records(folder, objects, args.pose_seeds, args.components, args.interpolate)
        return pose_summary(records, alpha, symmetric_objects(folder, objects, args.symmetric_below))
    return synthesis_table(folder, objects, args.centers, args.alpha, max(args.seeds[0], 3))


if __name__ == "__main__":
    raise SystemExit(main())
