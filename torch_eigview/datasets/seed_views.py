"""The seed views of every object of a manifest, read as a model records them: one path for
``eigview fit`` and Python.

:func:`read_seed_views` picks each object's views at the seed azimuths
(:func:`pick_seeds`), settles the size, channels and background rule, reads the views (and
their masks, unless the background is kept) and returns them with the
:class:`~torch_eigview.io.preprocessing.Preprocessing` that every later image must go
through: :meth:`~torch_eigview.method.FewViewEigenspace.fit_manifest` fits on them and
:meth:`~torch_eigview.method.FewViewEigenspace.save` records it, as ``eigview fit`` does.
:func:`read_images` reads any later image file through that preprocessing, as ``eigview
evaluate`` and ``eigview predict --model`` do.
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.datasets.background import background_rule
from torch_eigview.datasets.image_views import ViewDataset, _check_size, read_view, warn_aspect_changes
from torch_eigview.datasets.manifest import ViewEntry, ViewManifest
from torch_eigview.io.images import read_image
from torch_eigview.io.preprocessing import Preprocessing

__all__ = ["SeedViews", "pick_seeds", "read_images", "read_seed_views", "seed_angles"]

_TOL = 1e-6  # degrees: two azimuths this close are one pose


@dataclass(frozen=True)
class SeedViews:
    """Every object's seed views, read as its model's preprocessing says.

    Attributes:
        objects: the objects' names, in the manifest's order (the model's label names).
        views: per object its seed views ``(V, C, H, W)``, in the order of ``azimuths``.
        masks: per object its seed views' foreground ``(V, H, W)`` bool, or None where the
            background is kept (``"keep"``).
        azimuths: the seed azimuths in degrees, as given.
        angles: the seed angles the estimator takes (:func:`seed_angles`).
        preprocessing: what every image of the model goes through (size, channels,
            background rule).
        reason: why the background rule is what it is (``"as given"``, ``"the manifest
            lists masks"``, ``"the images have an alpha channel"``, ``"no masks given"``).
        manifest: the manifest's name.
    """

    objects: list[str]
    views: list[torch.Tensor]
    masks: list[torch.Tensor | None]
    azimuths: list[float]
    angles: list[float]
    preprocessing: Preprocessing
    reason: str
    manifest: str


def seed_angles(azimuths: Sequence[float]) -> list[float]:
    """The seed azimuths (degrees) as :meth:`~torch_eigview.method.FewViewEigenspace.fit`
    takes them: the first wrapped to (-180, 180], each next one the signed step (wrapped)
    from the one before, so that 350, 10 are -10, 10.

    Example:
        >>> seed_angles([350.0, 10.0]), seed_angles([0, 120, 240])
        ([-10.0, 10.0], [0.0, 120.0, 240.0])
    """
    from torch_eigview.geometry.angles import wrap_angle

    angles = [wrap_angle(azimuths[0])]
    for a, b in itertools.pairwise(azimuths):
        angles.append(angles[-1] + wrap_angle(float(b) - float(a)))
    return angles


def _same_pose(a: float, b: float) -> bool:
    from torch_eigview.geometry.angles import wrap_angle

    return abs(wrap_angle(a - b)) <= _TOL


def pick_seeds(manifest: ViewManifest, obj: str, azimuths: Sequence[float]) -> list[ViewEntry]:
    """The views of ``obj`` at ``azimuths`` (degrees), in that order.

    Raises:
        ValueError: the object has fewer views than seeds, none or several (elevations)
            at a seed azimuth; the message names the object, the manifest and what it has.
    """
    views = manifest.views(obj)
    have = ", ".join(f"{v.azimuth:g}" for v in views[:24]) + (", ..." if len(views) > 24 else "")
    if len(views) < len(azimuths):
        raise ValueError(
            f"object {obj!r} has {len(views)} view(s) in {manifest.name}, fewer than the {len(azimuths)} "
            f"seeds: azimuths {have}"
        )
    picked = []
    for az in azimuths:
        found = [v for v in views if _same_pose(v.azimuth, az)]
        if not found:
            raise ValueError(
                f"object {obj!r} has no view at the seed azimuth {az:g} degrees in {manifest.name}; "
                f"it has azimuths {have}"
            )
        if len(found) > 1:
            # Say "other elevations" only when they are; otherwise the azimuths themselves,
            # to full precision, so that 10 and 10.0000001 are not both shown as "10".
            elevations = {v.elevation for v in found if math.isfinite(v.elevation)}
            why = (
                "at other elevations"
                if len(elevations) == len(found)
                else f"azimuths {', '.join(f'{v.azimuth:.10g}' for v in found)}, within {_TOL:g} degrees of each other"
            )
            raise ValueError(
                f"object {obj!r} has {len(found)} views at the seed azimuth {az:g} degrees ({why}): "
                f"{', '.join(v.source for v in found)}; list one view per azimuth"
            )
        picked.append(found[0])
    return picked


def _check_azimuths(seeds: object) -> list[float]:
    if isinstance(seeds, (str, bytes)) or not isinstance(seeds, Sequence):
        raise TypeError(f"seeds must be a sequence of azimuths in degrees, got {type(seeds).__name__}")
    out = []
    for a in seeds:
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not math.isfinite(a):
            raise ValueError(f"seeds must be finite azimuths in degrees, got {list(seeds)!r}")
        out.append(float(a))
    if len(out) < 2:
        raise ValueError(f"seeds={out!r} needs two or more azimuths to synthesize from")
    return out


def _background_fields(background: object, tolerance: object) -> dict[str, object]:
    """The :class:`Preprocessing` fields of a background rule as Python gives it."""
    if background in ("keep", "auto"):
        colour = None
        rule = background
    elif isinstance(background, Sequence) and not isinstance(background, str):
        colour = tuple(background)
        if len(colour) not in (1, 3) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 <= v <= 1.0 for v in colour
        ):
            raise ValueError(f"background colour must be 1 or 3 values in [0, 1], got {background!r}")
        colour = tuple(float(v) for v in colour)
        rule = "colour"
    else:
        raise ValueError(
            f"background must be None, 'keep', 'auto' or a colour of 1 or 3 values in [0, 1], got {background!r}"
        )
    if tolerance is not None and rule == "keep":
        raise ValueError(f"tolerance={tolerance!r} goes with background 'auto' or a colour, not with 'keep'")
    return {"background": rule, "colour": colour, "tolerance": tolerance}


def _check_first_size(entry: ViewEntry) -> None:
    """Without ``size`` every view takes the first seed view's size: one past the side
    limit is named before any image is decoded."""
    from torch_eigview.check import SIDE_LIMIT, check_limit
    from torch_eigview.io.images import image_size

    hw = image_size(entry.path)
    if hw is not None:
        try:
            check_limit(
                max(hw), f"{entry.source}: the first seed view {entry.path}", "pixels per side", SIDE_LIMIT
            )
        except ValueError as exc:
            raise ValueError(
                f"{exc}; it is {hw[0]} x {hw[1]} (H x W) and sets every view's size: give size=(H, W) to "
                "resize the views"
            ) from None


def _read(
    entries: list[ViewEntry], size: tuple[int, int] | None, channels: int | None, prep: Preprocessing | None
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Views ``(V, C, H, W)`` and, unless ``prep`` keeps the background, masks ``(V, H, W)``;
    without ``size`` they must share the first one's size."""
    background = None if prep is None else background_rule(prep.background, prep.colour, prep.tolerance)
    read = [
        read_view(e.path, e.mask, size=size, channels=channels, source=e.source, background=background)
        for e in entries
    ]
    for e, (image, _) in zip(entries, read, strict=True):
        if image.shape != read[0][0].shape:
            raise ValueError(
                f"{e.source}: image {e.path} is (C, H, W)={tuple(image.shape)}, the first seed view "
                f"{entries[0].path} {tuple(read[0][0].shape)}; give size=(H, W) (and channels) to resize them"
            )
    views = torch.stack([image for image, _ in read])
    return views, None if background is None else torch.stack([mask[0] for _, mask in read])


def read_seed_views(
    manifest: ViewManifest | ViewDataset,
    seeds: Sequence[float],
    *,
    size: Sequence[int] | None = None,
    channels: int | None = None,
    background: str | Sequence[float] | None = None,
    tolerance: float | None = None,
) -> SeedViews:
    """Every object's views at the seed azimuths, and the preprocessing they were read with.

    Args:
        manifest: the views: a :class:`~torch_eigview.datasets.manifest.ViewManifest`, or a
            :class:`~torch_eigview.datasets.image_views.ViewDataset`, whose size and
            channels are taken where not given here (its background model is not: give
            ``background``).
        seeds: two or more seed azimuths in degrees, in the order of synthesis (round the
            circle: M >= 3 azimuths 360/M apart); each object needs one view at each.
        size: ``(H, W)`` every image is resized to; None: the first seed view's size.
        channels: 1 (gray) or 3 (RGB); None: the first seed view's.
        background: ``"keep"`` (pixels as read: black-background data), ``"auto"`` (each
            view's mask, from the manifest's mask column or an alpha channel, else the
            foreground estimated from the border's colours), a background colour of 1 or 3
            values in [0, 1], or None: ``"auto"`` when the manifest lists masks or the
            images have an alpha channel, else ``"keep"``. Except with ``"keep"`` the
            background is set to 0.
        tolerance: with ``"auto"`` or a colour, the largest colour distance (Euclidean,
            intensities in [0, 1]) that is still background; None: from the border's spread.

    Returns:
        The :class:`SeedViews`.

    Raises:
        TypeError, ValueError: a bad argument (the message names it), an object without a
            view at a seed azimuth, an image that cannot be read or is smaller than 2 x 2.

    Example:
        >>> seeds = read_seed_views(ViewManifest.from_csv("views.csv"), [0, 10])  # doctest: +SKIP
        >>> seeds.views[0].shape, seeds.preprocessing.background  # doctest: +SKIP
        (torch.Size([2, 1, 64, 64]), 'keep')
    """
    if isinstance(manifest, ViewDataset):
        size = manifest.size if size is None else size
        channels = manifest.channels if channels is None else channels
        manifest = manifest.manifest
    if not isinstance(manifest, ViewManifest):
        raise TypeError(f"manifest must be a ViewManifest or a ViewDataset, got {type(manifest).__name__}")
    azimuths = _check_azimuths(seeds)
    fields = None if background is None else _background_fields(background, tolerance)
    objects = manifest.objects
    picked = {obj: pick_seeds(manifest, obj, azimuths) for obj in objects}  # all checked first
    hw = _check_size(size)  # a pair of ints within the side limit, or None
    if hw is None:
        _check_first_size(picked[objects[0]][0])
    entries = [e for obj in objects for e in picked[obj]]
    warn_aspect_changes([e.path for e in entries], [e.source for e in entries])
    first, _ = _read(picked[objects[0]][:1], hw, channels, None)  # the size and channels
    if min(first.shape[2:]) < 2:  # the flow takes image gradients
        entry = picked[objects[0]][0]
        raise ValueError(
            f"{entry.source}: image {entry.path} is (H, W)={tuple(first.shape[2:])}, smaller than 2 x 2: "
            "give size=(H, W) to resize the views"
        )
    hw = hw or (int(first.shape[2]), int(first.shape[3]))
    channels = channels or int(first.shape[1])
    if fields is None:
        has_masks = any(e.mask is not None for e in manifest)
        alpha = read_image(picked[objects[0]][0].path, keep_alpha=True).shape[0] in (2, 4)
        rule = "auto" if has_masks or alpha else "keep"
        if rule == "keep" and tolerance is not None:
            raise ValueError(
                f"tolerance={tolerance!r} goes with background 'auto' or a colour; the views have no masks, "
                "so the background is kept: give background='auto' or a colour"
            )
        reason = (
            "the manifest lists masks"
            if has_masks
            else "the images have an alpha channel"
            if alpha
            else "no masks given"
        )
        fields = _background_fields(rule, tolerance)
    else:
        reason = "as given"
    prep = Preprocessing(hw, channels, **fields)  # type: ignore[arg-type]
    kept = prep.background == "keep"
    read = [_read(picked[obj], hw, channels, None if kept else prep) for obj in objects]
    return SeedViews(
        objects=objects,
        views=[views for views, _ in read],
        masks=[masks for _, masks in read],
        azimuths=azimuths,
        angles=seed_angles(azimuths),
        preprocessing=prep,
        reason=reason,
        manifest=manifest.name,
    )


def read_images(
    paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    preprocessing: Preprocessing,
    *,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """Image files as a model's input: resized, background rule applied and channels
    converted as ``preprocessing`` says, exactly as ``eigview evaluate`` and ``eigview
    predict --model`` read them (the alpha channel as the mask, else the foreground
    estimated, unless the background is kept).

    Args:
        paths: one image file or a sequence of them.
        preprocessing: the model's (``FewViewEigenspace.preprocessing_``,
            ``Model.preprocessing``).
        dtype: the floating dtype of the result.

    Returns:
        ``(B, C, H, W)`` of ``dtype`` in [0, 1], ``(C, H, W)`` = ``preprocessing.image_shape``.

    Raises:
        TypeError: ``preprocessing`` is not a :class:`Preprocessing`.
        ValueError: a file cannot be read, or its background leaves no object; the message
            names it.
    """
    if not isinstance(preprocessing, Preprocessing):
        raise TypeError(f"preprocessing must be a Preprocessing, got {type(preprocessing).__name__}")
    files = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    rule = background_rule(preprocessing.background, preprocessing.colour, preprocessing.tolerance)
    images = [
        read_view(
            path, size=preprocessing.size, channels=preprocessing.channels, dtype=dtype, background=rule
        )[0]
        for path in files
    ]
    return torch.stack(images) if images else torch.empty((0, *preprocessing.image_shape), dtype=dtype)
