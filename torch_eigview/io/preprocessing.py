"""What a model does to an image file before its projection, recorded with the model.

``eigview fit`` writes a :class:`Preprocessing` into the model file's metadata and
``eigview export`` into the ONNX graph's, so that ``eigview evaluate`` and ``eigview
predict`` turn a new image into exactly the input the gallery was built from. Torch-free:
the onnxruntime-only ``eigview predict`` resizes with Pillow (:func:`prepare_array`),
whose antialiased bilinear filter is the one
:class:`~torch_eigview.datasets.image_views.ViewDataset` applies with torch (the same
triangle filter widened by the scale; the two agree to float32 rounding), and finds the
foreground with the numpy rule :class:`~torch_eigview.datasets.background.BackgroundModel`
itself uses (:func:`~torch_eigview.io.foreground.estimate_foreground`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from torch_eigview.io.foreground import LUMA, check_mask_border, colour_in_channels, estimate_foreground
from torch_eigview.io.images import read_image, to_unit_float

__all__ = ["BACKGROUNDS", "RESIZE_RULE", "Preprocessing", "prepare_array", "prepare_file"]

RESIZE_RULE = "bilinear-antialias"
"""Images: antialiased bilinear (each output pixel averages its footprint); masks: the
area fraction of object under each output pixel, thresholded at one half."""

BACKGROUNDS = ("keep", "auto", "colour")
"""``"keep"``: the pixels as read, masks not applied (the black-background data sets' rule).
``"auto"``: the view's mask (a manifest's mask image, an alpha channel) where it has one,
else the foreground estimated from the colours of the image border; the background is then
set to 0. ``"colour"``: the same with the recorded background colour in place of the
border's colours."""


@dataclass(frozen=True)
class Preprocessing:
    """The steps from an image file to a model's input, in order.

    Attributes:
        size: ``(H, W)`` every image is resized to (:data:`RESIZE_RULE`).
        channels: ``C`` of the model's input: 1 (RGB to gray, BT.709) or 3 (gray repeated).
        background: what is done with the background (:data:`BACKGROUNDS`).
        unit_norm: whether the model scales each image to unit L2 norm (done by its
            projection, recorded so that a reader knows what the codes mean).
        colour: with ``background="colour"``, the background colour (1 or 3 values in
            [0, 1]); None otherwise.
        tolerance: the largest distance from a background colour (Euclidean over the
            channels, intensities in [0, 1]) that is background, or None for the border's
            spread; None with ``"keep"``.

    Example:
        >>> p = Preprocessing((4, 6), 1)
        >>> Preprocessing.from_json(json.loads(json.dumps(p.to_json()))) == p
        True
    """

    size: tuple[int, int]
    channels: int
    background: str = "keep"
    unit_norm: bool = True
    resize: str = RESIZE_RULE
    colour: tuple[float, ...] | None = None
    tolerance: float | None = None

    def __post_init__(self) -> None:
        if not (
            isinstance(self.size, tuple)
            and len(self.size) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in self.size)
        ):
            raise ValueError(f"size must be (H, W) with ints >= 1, got {self.size!r}")
        if self.channels not in (1, 3) or isinstance(self.channels, bool):
            raise ValueError(f"channels must be 1 or 3, got {self.channels!r}")
        if self.background not in BACKGROUNDS:
            raise ValueError(f"background must be one of {BACKGROUNDS}, got {self.background!r}")
        if self.resize != RESIZE_RULE:
            raise ValueError(f"resize must be {RESIZE_RULE!r}, got {self.resize!r}")
        if not isinstance(self.unit_norm, bool):
            raise ValueError(f"unit_norm must be a bool, got {self.unit_norm!r}")
        self._check_background()

    def _check_background(self) -> None:
        if (self.background == "colour") != (self.colour is not None):
            raise ValueError(
                f"colour must be given with background='colour' and only then, got background="
                f"{self.background!r} and colour={self.colour!r}"
            )
        if self.colour is not None:
            if not (
                isinstance(self.colour, tuple)
                and len(self.colour) in (1, 3)
                and all(_is_number(v) and 0.0 <= v <= 1.0 for v in self.colour)
            ):
                raise ValueError(f"colour must be 1 or 3 values in [0, 1], got {self.colour!r}")
        if self.tolerance is not None:
            if self.background == "keep":
                raise ValueError("tolerance goes with background 'auto' or 'colour', not 'keep'")
            if not (_is_number(self.tolerance) and 0.0 < self.tolerance < math.inf):
                raise ValueError(f"tolerance must be a positive number, got {self.tolerance!r}")

    @property
    def image_shape(self) -> tuple[int, int, int]:
        """``(C, H, W)`` of the model's input."""
        return (self.channels, *self.size)

    def to_json(self) -> dict[str, object]:
        record: dict[str, object] = {
            "size": list(self.size),
            "channels": self.channels,
            "background": self.background,
            "unit_norm": self.unit_norm,
            "resize": self.resize,
        }
        # Absent, not null, with "keep": such a record reads as before backgrounds.
        if self.colour is not None:
            record["colour"] = list(self.colour)
        if self.tolerance is not None:
            record["tolerance"] = self.tolerance
        return record

    @classmethod
    def from_json(cls, record: object, source: str = "the model") -> Preprocessing:
        """Parses :meth:`to_json`'s record; ``source`` names the file in errors.

        Raises:
            ValueError: the record is not one (a missing key, a bad value).
        """
        try:
            if not isinstance(record, Mapping):
                raise ValueError(f"{record!r} is not a mapping")
            size = record["size"]
            if not isinstance(size, list) or len(size) != 2:
                raise ValueError(f"size {size!r} is not [H, W]")
            colour = record.get("colour")  # absent in files written before backgrounds
            if colour is not None and not isinstance(colour, list):
                raise ValueError(f"colour {colour!r} is not a list")
            return cls(
                (size[0], size[1]),
                record["channels"],
                record["background"],
                record["unit_norm"],
                record["resize"],
                None if colour is None else tuple(colour),
                record.get("tolerance"),
            )
        except KeyError as exc:
            raise ValueError(
                f"{source} has a damaged preprocessing record: {exc} is missing (a field every record holds)"
            ) from None
        except ValueError as exc:
            raise ValueError(f"{source} has a damaged preprocessing record: {exc}") from None

    def to_prop(self) -> str:
        """The record as one ONNX ``metadata_props`` string."""
        return json.dumps(self.to_json())


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _resize_plane(plane: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    from PIL import Image

    image = Image.fromarray(np.ascontiguousarray(plane, dtype=np.float32))  # mode "F"
    return np.asarray(image.resize((size[1], size[0]), Image.Resampling.BILINEAR), dtype=np.float32)


def _convert(work: np.ndarray, channels: int) -> np.ndarray:
    if channels == 3 and work.shape[0] == 1:
        return np.repeat(work, 3, axis=0)
    if channels == 1 and work.shape[0] == 3:
        return np.clip(np.tensordot(LUMA, work, axes=1)[None], 0.0, 1.0)
    return work


def _resize(work: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    if tuple(work.shape[1:]) == size:
        return work
    return np.clip(np.stack([_resize_plane(p, size) for p in work]), 0.0, 1.0).astype(np.float32)


def prepare_array(image: np.ndarray, prep: Preprocessing, mask: np.ndarray | None = None) -> np.ndarray:
    """An image ``(C, H, W)`` float in ``[0, 1]`` (alpha dropped) as the model's input, without torch.

    With ``prep.background`` ``"keep"``: converts the channels, then resizes each plane
    with Pillow's antialiased bilinear filter (float32), clamped to ``[0, 1]`` as
    :class:`~torch_eigview.datasets.image_views.ViewDataset` does. Otherwise, as
    ``ViewDataset`` with a background model: resizes, sets the background to 0 (outside
    ``mask``, resized to the fraction of object under each pixel and thresholded at one
    half, else outside the foreground estimated in the image's own channels), then
    converts the channels.

    Args:
        image: ``(C, H, W)`` with C 1 or 3.
        prep: the model's preprocessing.
        mask: optional ``(H, W)`` bool foreground of ``image`` (an alpha channel's), True
            on the object; unused with ``"keep"``; all True (an opaque alpha channel) is
            no mask.

    Returns:
        ``prep.image_shape`` float32.

    Raises:
        ValueError: ``image`` is not ``(C, H, W)`` with C 1 or 3, ``mask`` has another
            size, the mask is all background or the background leaves no object.
    """
    if not isinstance(prep, Preprocessing):
        raise TypeError(f"prep must be a Preprocessing, got {type(prep).__name__}")
    if image.ndim != 3 or image.shape[0] not in (1, 3):
        raise ValueError(f"image must be (C, H, W) with C 1 or 3, got shape {image.shape}")
    if image.size and not (np.isfinite(image).all() and 0.0 <= image.min() and image.max() <= 1.0):
        raise ValueError(
            f"image must hold finite values in [0, 1], got min={image.min()!r}, max={image.max()!r}"
        )
    if mask is not None and mask.shape != image.shape[1:]:
        raise ValueError(f"mask must have the image's size (H, W)={image.shape[1:]}, got {mask.shape}")
    work = image.astype(np.float32, copy=False)
    if prep.background == "keep":
        return np.ascontiguousarray(_resize(_convert(work, prep.channels), prep.size))
    work = _resize(work, prep.size)
    if mask is not None and mask.all():
        mask = None  # an opaque alpha channel marks no background: as read_view, no mask
    if mask is None:
        colour = None if prep.colour is None else colour_in_channels(prep.colour, work.shape[0])
        fg = estimate_foreground(work, colour, prep.tolerance)
    else:
        fg = mask if mask.shape == prep.size else _resize_plane(mask.astype(np.float32), prep.size) >= 0.5
        if not fg.any():
            raise ValueError("the mask is all background (no object pixel): a view must show its object")
    return np.ascontiguousarray(_convert(np.where(fg[None], work, np.float32(0.0)), prep.channels))


def prepare_file(path: str | os.PathLike[str], prep: Preprocessing) -> np.ndarray:
    """An image file as the model's input, without torch: read (the alpha channel as the
    mask where the background is not kept), then :func:`prepare_array`. ``eigview predict``
    (both runtimes) and :meth:`~torch_eigview.io.model.Model.predict_files` read so.

    Returns:
        ``prep.image_shape`` float32.

    Raises:
        ValueError: the file cannot be read, or its mask or background leaves no object;
            the message names the file.
    """
    arr = read_image(path, keep_alpha=prep.background != "keep")
    mask = arr[-1] > 0 if arr.shape[0] in (2, 4) else None  # the alpha channel decides
    colour = arr[:-1] if mask is not None else arr
    if mask is not None and not mask.all():  # an opaque alpha is no mask (prepare_array)
        check_mask_border(mask, f"the alpha channel of {os.fspath(path)}")
    try:
        return prepare_array(to_unit_float(colour, np.float32), prep, mask)
    except ValueError as exc:
        raise ValueError(f"image {os.fspath(path)}: {exc}") from None
