"""What :class:`~torch_eigview.method.estimator.FewViewEigenspace` takes in, validated.

Seed views, their angles and labels for ``fit``; blocks of gallery views for
``fit_blocks``; and the hyperparameters, checked by ``fit`` (scikit-learn's convention).
"""

from __future__ import annotations

import itertools
import math
import numbers
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import torch
from torch.utils.data import DataLoader, Dataset, RandomSampler

from torch_eigview.check import (
    VIEW_LIMIT,
    check_float_tensor,
    check_int,
    check_limit,
    check_n_components,
    check_ndim,
    check_number,
)
from torch_eigview.geometry.angles import AROUND_SEEDS, angle_range, around_seeds, wrap_angle, wrap_degrees
from torch_eigview.synthesis import Circle, SynthesisOptions
from torch_eigview.warp.normalize import FILLED_FRAME, box_fill, foreground_mask, seed_foreground

__all__ = [
    "ALL_COMPONENTS",
    "Params",
    "block_item",
    "block_source",
    "check_angles",
    "check_circle_angles",
    "check_labels",
    "check_reach",
    "check_seed_masks",
    "check_seeds",
    "check_synth",
    "resolve_components",
    "seed_steps",
    "warn_unnormalized_seeds",
    "wrap_degrees",
]

ALL_COMPONENTS = math.nextafter(1.0, 0.0)
"""The energy fraction ``n_components=None`` stands for: every component above rounding.

The eigenspaces keep the smallest k whose eigenvalues reach the fraction, at most the
rank; no partial sum of the kept eigenvalues reaches the largest float below 1 before the
last eigenvalue above rounding level is in."""


def resolve_components(n_components: object) -> int | float:
    """``n_components`` validated: an int >= 1, a fraction in (0, 1), or None for :data:`ALL_COMPONENTS`."""
    return ALL_COMPONENTS if n_components is None else check_n_components(n_components)


@dataclass(frozen=True)
class Params:
    """The hyperparameters of :class:`FewViewEigenspace`, validated."""

    n_components: int | float
    synth: tuple[float, float, float] | str | Circle | None
    options: SynthesisOptions
    unit_norm: bool
    kernel: str | None
    gamma: float | str | None
    synth_follows_seeds: bool
    max_views: int
    workers: int = 0
    worker_kind: str = "thread"
    max_rank: int = 512
    degree: int = 3

    def thetas(self, steps: list[float]) -> list[float]:
        """Gallery angles relative to the first seed, for seeds ``steps`` apart: with
        :data:`AROUND_SEEDS` every degree from 20° before the first seed to 20° past the
        last (:func:`~torch_eigview.geometry.angles.around_seeds`); with (start, stop,
        step) that range (as ``CoilExperiment.synth_angles``: each seed past the second
        extends it on its side by its step, when ``synth_follows_seeds``)."""
        assert self.synth is not None and not isinstance(self.synth, Circle)
        if isinstance(self.synth, str):
            return angle_range(*around_seeds(steps), "synth")
        start, stop, step = self.synth
        if self.synth_follows_seeds:
            extra = (len(steps) - 1) * steps[0] if len(set(steps)) == 1 else sum(steps[1:])
            start, stop = start + min(extra, 0.0), stop + max(extra, 0.0)
        return angle_range(start, stop, step, "synth")


def check_synth(
    synth: object, name: str = "synth", *, around: bool = False
) -> tuple[float, float, float] | str | Circle | None:
    """None, (start, stop, step) finite degrees with step > 0 and start <= stop, or, with
    ``around``, :data:`AROUND_SEEDS` and the full circle (``"circle"``, returned as
    ``Circle()``, or a :class:`~torch_eigview.synthesis.Circle`); the messages name the
    argument ``name``."""
    if synth is None or (around and isinstance(synth, str) and synth == AROUND_SEEDS):
        return synth
    if around and (isinstance(synth, Circle) or (isinstance(synth, str) and synth == "circle")):
        circle = synth if isinstance(synth, Circle) else Circle()
        check_limit(360.0 / circle.step, name, "views per object", VIEW_LIMIT)
        return circle
    if not isinstance(synth, Sequence) or isinstance(synth, str) or len(synth) != 3:
        also = f", {AROUND_SEEDS!r}, 'circle', a Circle or None" if around else ""
        raise ValueError(f"{name} must be (start, stop, step) in degrees{also}, got {synth!r}")
    start, stop, step = (check_number(v, f"{name}[{i}]") for i, v in enumerate(synth))
    if not all(math.isfinite(v) for v in (start, stop, step)):
        raise ValueError(f"{name} must hold finite angles, got {synth!r}")
    if not step > 0:
        raise ValueError(f"{name} step must be positive, got {step}")
    if stop < start:
        raise ValueError(f"{name} must have start <= stop, got start={start}, stop={stop}")
    check_limit((stop - start) / step + 1, name, "views per object", VIEW_LIMIT)
    return start, stop, step


def check_seeds(seeds: object) -> list[torch.Tensor]:
    """One (V_o, C, H, W) tensor per object, of one view shape and dtype."""
    if isinstance(seeds, torch.Tensor):
        check_float_tensor(seeds, "seeds")
        check_ndim(seeds, "seeds", (5,), "(O, V, C, H, W)")
        objects = list(seeds.detach().unbind(0))
    elif isinstance(seeds, Sequence) and not isinstance(seeds, str):
        objects = []
        for i, s in enumerate(seeds):
            check_float_tensor(s, f"seeds[{i}]")
            check_ndim(s, f"seeds[{i}]", (4,), "(V, C, H, W)")
            objects.append(s.detach())
    else:
        raise TypeError(
            f"seeds must be an (O, V, C, H, W) tensor or a sequence of (V, C, H, W) tensors, got {type(seeds).__name__}"
        )
    if not objects:
        raise ValueError("seeds must hold at least one object, got none")
    first = objects[0]
    for i, s in enumerate(objects):
        if s.shape[1:] != first.shape[1:] or s.dtype != first.dtype or s.shape[0] < 1:
            raise ValueError(
                f"seeds[{i}] must hold V >= 1 views of shape {tuple(first.shape[1:])} and dtype {first.dtype} "
                f"like seeds[0], got shape {tuple(s.shape)} and dtype {s.dtype}"
            )
    return objects


def check_seed_masks(masks: object, objects: list[torch.Tensor]) -> list[torch.Tensor | None]:
    """Per object its (V_o, H, W) bool seed masks or None (the brightness threshold).

    ``masks`` is None, an (O, V, H, W) bool tensor, or a sequence of O entries, each None
    or a (V_o, H, W) bool tensor; every mask must show its object (a True pixel).
    """
    if masks is None:
        return [None] * len(objects)
    if isinstance(masks, torch.Tensor):
        check_ndim(masks, "masks", (4,), "(O, V, H, W)")
        per_object: list[object] = list(masks.detach().unbind(0))
    elif isinstance(masks, Sequence) and not isinstance(masks, str):
        per_object = list(masks)
    else:
        raise TypeError(
            f"masks must be None, an (O, V, H, W) bool tensor or a sequence of (V, H, W) ones, got {type(masks).__name__}"
        )
    if len(per_object) != len(objects):
        raise ValueError(f"masks must hold one entry per object ({len(objects)}), got {len(per_object)}")
    out: list[torch.Tensor | None] = []
    for i, (m, views) in enumerate(zip(per_object, objects, strict=True)):
        if m is None:
            out.append(None)
            continue
        try:
            seed_foreground(views, m, 0.0)  # a (V, H, W) bool tensor
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"masks[{i}] (of seeds[{i}]): {exc}") from None
        assert isinstance(m, torch.Tensor)
        empty = (~m.flatten(1).any(dim=1)).nonzero().flatten().tolist()
        if empty:
            raise ValueError(
                f"masks[{i}][{empty[0]}] is all background (no True pixel): a view must show its object"
            )
        out.append(m.detach())
    return out


def check_angles(
    seed_angles: object, objects: list[torch.Tensor], synthesis: bool = False
) -> list[list[float]]:
    """Per object its seed views' angles (degrees): one shared list, or one list per object;
    with ``synthesis``, consecutive ones a seed pair can synthesize from (:func:`seed_steps`)."""
    if isinstance(seed_angles, torch.Tensor):
        seed_angles = seed_angles.detach().tolist()
    if not isinstance(seed_angles, Sequence) or isinstance(seed_angles, str) or not seed_angles:
        raise TypeError(f"seed_angles must be a non-empty sequence of angles in degrees, got {seed_angles!r}")
    shared = isinstance(seed_angles[0], numbers.Real)
    per_object = [seed_angles] * len(objects) if shared else list(seed_angles)
    if len(per_object) != len(objects):
        raise ValueError(
            f"seed_angles must hold one list of angles per object ({len(objects)}), got {len(per_object)}"
        )
    out = []
    for i, (angles, views) in enumerate(zip(per_object, objects, strict=True)):
        what = "seed_angles" if shared else f"seed_angles[{i}]"
        if not isinstance(angles, Sequence) or len(angles) != views.shape[0]:
            raise ValueError(
                f"{what} must hold one angle per seed view of object {i} ({views.shape[0]}), got {angles!r}"
            )
        values = [check_number(a, what) for a in angles]
        if not all(math.isfinite(a) for a in values):
            raise ValueError(f"{what} must hold finite angles, got {angles!r}")
        if synthesis:
            seed_steps(values, what)
        out.append(values)
    return out


def check_labels(labels: object, n_objects: int) -> tuple[list[int], list[str] | None]:
    """The objects' int labels and, for labels given as names, the names (the labels are
    then 0 … O − 1); names must be distinct, as must ints."""
    if labels is None:
        return list(range(n_objects)), None
    if isinstance(labels, torch.Tensor):
        labels = labels.detach().tolist()
    if not isinstance(labels, Sequence) or isinstance(labels, str) or len(labels) != n_objects:
        raise ValueError(f"labels must hold one int or name per object ({n_objects}), got {labels!r}")
    if all(isinstance(v, str) for v in labels):
        names = list(labels)
        if len(set(names)) != len(names):
            dup = sorted({v for v in names if names.count(v) > 1})
            raise ValueError(f"labels must name each object once, got {dup} more than once")
        return list(range(n_objects)), names
    ints = [check_int(v, f"labels[{i}]") for i, v in enumerate(labels)]
    return ints, None


def check_circle_angles(angles: list[list[float]]) -> None:
    """Each object's seed angles go once round the circle, 360/M apart, M >= 3."""
    for i, values in enumerate(angles):
        m = len(values)
        if m < 3:
            raise ValueError(
                f"seed_angles[{i}] must hold M >= 3 angles round the circle for synth='circle' "
                f"(seeds 180 degrees apart leave Eq. 7 singular), got {values}"
            )
        off = [a for k, a in enumerate(values) if abs(wrap_angle(a - values[0] - k * 360.0 / m)) > 1e-6]
        if off:
            raise ValueError(
                f"seed_angles[{i}] must be {m} angles 360/{m} = {360.0 / m:g} degrees apart going round the "
                f"circle from {values[0]:g} for synth='circle', got {values}"
            )


def warn_unnormalized_seeds(objects: list[torch.Tensor], options: SynthesisOptions) -> None:
    """Warns when ``options.extent=True`` would size-normalize the synthesized views of seed
    views that are not size-normalized themselves (``"auto"`` decides from the seeds).

    The gallery would then hold every view scaled to fill the frame while the seed views
    and test views like them are not: they lie far from every gallery view (measured on
    the synthetic renderer at 32 px: even the seed views' own nearest gallery view was
    20° off, at distance 0.2 against 1e-4 with ``extent=False``). COIL's processed images
    fill the frame (fill 1.0) and pass.

    Args:
        objects: per object its (V, C, H, W) seed views.
        options: the synthesis options; nothing is checked unless ``extent`` is True.
    """
    if options.extent is not True:
        return
    fills = torch.cat([box_fill(foreground_mask(v, options.background)) for v in objects])
    if float(fills.min()) < FILLED_FRAME:  # what extent="auto" would not normalize
        warnings.warn(
            f"options.extent=True size-normalizes the synthesized views, but a seed view's object "
            f"(pixels above background={options.background}) fills only {float(fills.min()):.0%} of "
            "the frame: the gallery will not match views like the seeds. Pass "
            "SynthesisOptions(extent=False), or size-normalize the seed and test views "
            "(torch_eigview.warp.normalize.normalize_extent)",
            UserWarning,
            stacklevel=3,
        )


def seed_steps(angles: list[float], what: str = "seed_angles") -> list[float]:
    """The angles between consecutive seed views, each one a pair can synthesize from, over
    less than a half turn (``synthesize_views``'s seeds)."""
    steps = [b - a for a, b in itertools.pairwise(angles)]
    for i, step in enumerate(steps):
        if math.remainder(step, 180.0) == 0:  # sin(step) = 0: the pair sees no depth
            raise ValueError(
                f"{what} must put consecutive seed views apart by an angle that is not a multiple of 180 "
                f"degrees to synthesize from them, got {angles[i]} and {angles[i + 1]} (seeds {i} and {i + 1})"
            )
    if abs(sum(steps)) >= 180:
        raise ValueError(
            f"{what} must span less than 180 degrees to synthesize from (the limit of "
            f"synthesize_views), got {angles}"
        )
    return steps


def check_reach(seed_angles: list[float], thetas: list[float], held: list[float]) -> None:
    """Every angle to synthesize within a quarter turn of the seed that synthesizes it: a
    seed pair makes the angles before it (the first pair) or past it (the last) from its
    first seed, and only up to 90 degrees from it does that seed see the same side.

    Raises:
        ValueError: naming ``synth`` or ``reject_poses``, the seeds and how far they reach.
    """
    seeds = [a - seed_angles[0] for a in seed_angles]
    d = 1.0 if seeds[1] > 0 else -1.0  # the direction the seeds go
    last_first = seeds[-2]  # the end pair's own first seed
    for name, angles in (("synth", thetas), ("reject_poses", held)):
        if not angles:
            continue
        before = -d * (min(angles) if d > 0 else max(angles))  # before the first seed, from it
        past = d * ((max(angles) if d > 0 else min(angles)) - last_first)
        reach = max(before, past)
        if reach >= 90:
            raise ValueError(
                f"{name} asks for views {reach:g} degrees from the seed that would synthesize them, with "
                f"seeds at {', '.join(f'{a:g}' for a in seed_angles)} degrees; a seed pair synthesizes less "
                "than 90 degrees from its first seed (beyond, the seeds show the object's other side): "
                f"narrow {name}, or add seed views nearer the ends"
            )


def block_source(blocks: object) -> Callable[[], Iterable[object]]:
    """A callable giving a fresh pass over ``blocks`` (see ``FewViewEigenspace.fit_blocks``)."""
    if isinstance(blocks, DataLoader) and isinstance(blocks.sampler, RandomSampler):
        raise ValueError(
            "blocks is a DataLoader that shuffles: every pass must yield the same views in the same order "
            "(shuffle=False)"
        )
    if isinstance(blocks, torch.Tensor):
        raise TypeError("blocks must be an iterable of view blocks, got one tensor (wrap it in a list)")
    if callable(blocks) and not isinstance(blocks, Iterable):
        return blocks
    if isinstance(blocks, Dataset) and hasattr(blocks, "__len__") and not isinstance(blocks, Iterable):
        # A map-style Dataset (a ViewDataset): one item per block, read afresh each pass.
        return lambda: (blocks[i] for i in range(len(blocks)))
    if not isinstance(blocks, Iterable):
        raise TypeError(
            f"blocks must be an iterable of view blocks or a callable returning one, got {type(blocks).__name__}"
        )
    if iter(blocks) is blocks:  # one pass only: hold it
        items = list(blocks)
        return lambda: items
    return lambda: blocks


# The keys of a ViewDataset item (or of a DataLoader batch of them, default collate) that
# fit_blocks reads: the views, the object's name (the label) and the azimuth (the pose).
VIEW_ITEM_KEYS = ("image", "object", "azimuth")


def _view_item_parts(item: Mapping[object, object], index: int, names: dict[str, int]) -> list[object]:
    """A ViewDataset item (one view) or a collated batch of them → [views, labels, poses]."""
    what = f"blocks[{index}]"
    if "image" not in item:
        raise ValueError(
            f"{what} is a dict without the key 'image': a dict block must be a ViewDataset item or a "
            f"DataLoader batch of them, with keys {VIEW_ITEM_KEYS} (got keys {sorted(map(str, item))})"
        )
    views = check_float_tensor(item["image"], f"{what}['image']")
    single = views.ndim == 3  # one ViewDataset item, (C, H, W)
    parts: list[object] = [views[None] if single else views]
    n = parts[0].shape[0]  # type: ignore[attr-defined]
    if "object" in item:
        objects = [item["object"]] if single or isinstance(item["object"], str) else item["object"]
        if not isinstance(objects, Sequence) or not all(isinstance(o, str) for o in objects):
            raise TypeError(
                f"{what}['object'] must be the object's name (str), or a list of names for a batch, "
                f"got {type(item['object']).__name__}"
            )
        # Names become labels 0, 1, … in order of first appearance; the caller keeps
        # ``names`` across the blocks of a pass, so every block labels alike.
        parts.append(torch.tensor([names.setdefault(o, len(names)) for o in objects], dtype=torch.int64))
    else:
        parts.append(torch.full((n,), index))  # as a bare tensor's views
    if "azimuth" in item:
        parts.append(torch.as_tensor(item["azimuth"], dtype=torch.float64).reshape(-1))
    return parts


def block_item(
    item: object, index: int, names: dict[str, int] | None = None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(B, C, H, W) views, (B,) int64 labels and (B,) float64 poses of one block.

    A block is views, ``(views, labels[, poses])``, or a dict as
    :class:`~torch_eigview.datasets.ViewDataset` yields it (one view) or a ``DataLoader``
    collates it (a batch): ``image`` gives the views, ``object`` the label (names are
    numbered in ``names``, in order of first appearance) and ``azimuth`` the pose.
    """
    what = f"blocks[{index}]"
    if isinstance(item, Mapping):
        parts = _view_item_parts(item, index, {} if names is None else names)
    else:
        parts = list(item) if isinstance(item, (tuple, list)) else [item]
    if not 1 <= len(parts) <= 3:
        raise ValueError(
            f"{what} must be views, (views, labels) or (views, labels, poses), got {len(parts)} parts"
        )
    views = check_float_tensor(parts[0], f"{what} views")
    check_ndim(views, f"{what} views", (4,), "(B, C, H, W)")
    n = views.shape[0]
    labels = torch.as_tensor(parts[1]) if len(parts) > 1 else torch.full((n,), index)
    poses = (
        torch.as_tensor(parts[2], dtype=torch.float64)
        if len(parts) > 2
        else torch.zeros(n, dtype=torch.float64)
    )
    if labels.is_floating_point() or labels.is_complex() or tuple(labels.shape) != (n,):
        raise ValueError(f"{what} labels must be ({n},) integers, got {labels.dtype} {tuple(labels.shape)}")
    if tuple(poses.shape) != (n,):
        raise ValueError(f"{what} poses must have shape ({n},), got {tuple(poses.shape)}")
    return views.detach(), labels.to(views.device, torch.int64), poses.to(views.device)
