"""What a model does to an image file before its projection, recorded with the model.

``eigview fit`` writes a :class:`Preprocessing` into the model file's metadata and
``eigview export`` into the ONNX graph's, so that ``eigview evaluate`` and ``eigview
predict`` turn a new image into exactly the input the gallery was built from. Torch-free:
the onnxruntime-only ``eigview predict`` resizes with Pillow (:func:`prepare_array`),
whose antialiased bilinear filter is the one
:class:`~torch_eigview.datasets.image_views.ViewDataset` applies with torch (the same
triangle filter widened by the scale; the two agree to float32 rounding).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["BACKGROUNDS", "RESIZE_RULE", "Preprocessing", "prepare_array"]

RESIZE_RULE = "bilinear-antialias"
"""Images: antialiased bilinear (each output pixel averages its footprint); masks: the
area fraction of object under each output pixel, thresholded at one half."""

BACKGROUNDS = ("keep",)
"""``"keep"``: the pixels as read, masks not applied (the black-background data sets' rule)."""

# ITU-R BT.709 luma, the weights of skimage.color.rgb2gray (as ViewDataset's).
_LUMA = np.array([0.2125, 0.7154, 0.0721], dtype=np.float32)


@dataclass(frozen=True)
class Preprocessing:
    """The steps from an image file to a model's input, in order.

    Attributes:
        size: ``(H, W)`` every image is resized to (:data:`RESIZE_RULE`).
        channels: ``C`` of the model's input: 1 (RGB to gray, BT.709) or 3 (gray repeated).
        background: what is done with the background (:data:`BACKGROUNDS`).
        unit_norm: whether the model scales each image to unit L2 norm (done by its
            projection, recorded so that a reader knows what the codes mean).

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

    @property
    def image_shape(self) -> tuple[int, int, int]:
        """``(C, H, W)`` of the model's input."""
        return (self.channels, *self.size)

    def to_json(self) -> dict[str, object]:
        return {
            "size": list(self.size),
            "channels": self.channels,
            "background": self.background,
            "unit_norm": self.unit_norm,
            "resize": self.resize,
        }

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
            return cls(
                (size[0], size[1]),
                record["channels"],
                record["background"],
                record["unit_norm"],
                record["resize"],
            )
        except (KeyError, ValueError) as exc:
            raise ValueError(f"{source} has a damaged preprocessing record: {exc}") from None

    def to_prop(self) -> str:
        """The record as one ONNX ``metadata_props`` string."""
        return json.dumps(self.to_json())


def _resize_plane(plane: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    from PIL import Image

    image = Image.fromarray(np.ascontiguousarray(plane, dtype=np.float32))  # mode "F"
    return np.asarray(image.resize((size[1], size[0]), Image.Resampling.BILINEAR), dtype=np.float32)


def prepare_array(image: np.ndarray, prep: Preprocessing) -> np.ndarray:
    """An image ``(C, H, W)`` float in ``[0, 1]`` (alpha dropped) as the model's input, without torch.

    Converts the channels, then resizes each plane with Pillow's antialiased bilinear
    filter (float32), clamped to ``[0, 1]`` as :class:`~torch_eigview.datasets.image_views.ViewDataset` does.

    Returns:
        ``prep.image_shape`` float32.

    Raises:
        ValueError: ``image`` is not ``(C, H, W)`` with C 1 or 3.
    """
    if image.ndim != 3 or image.shape[0] not in (1, 3):
        raise ValueError(f"image must be (C, H, W) with C 1 or 3, got shape {image.shape}")
    work = image.astype(np.float32, copy=False)
    if prep.channels == 3 and work.shape[0] == 1:
        work = np.repeat(work, 3, axis=0)
    elif prep.channels == 1 and work.shape[0] == 3:
        work = np.clip(np.tensordot(_LUMA, work, axes=1)[None], 0.0, 1.0)
    if tuple(work.shape[1:]) == prep.size:
        return np.ascontiguousarray(work)
    planes = [_resize_plane(p, prep.size) for p in work]
    return np.clip(np.stack(planes), 0.0, 1.0).astype(np.float32)
