"""Foreground masks and a constant background: the background model of a set of views.

With masks (a segmentation tool's, an RGBA image's alpha, a renderer's), the masks decide
the foreground. Without, :class:`BackgroundModel` estimates them: the background colours
are taken from the image border, where a turntable photograph shows the backdrop and the
table and rarely the object. Each colour is the channel-wise median of the border pixels
still unexplained (the first is the backdrop's, the second typically the table's or the
cloth's), and its tolerance comes from the spread of the border pixels it explains, so a
textured backdrop's own variation stays background. A pixel farther than every colour's
tolerance is foreground; the mask is then cleaned: foreground specks smaller than
``min_fraction`` of the image (backdrop texture that passed the tolerance) are dropped and
background holes as small inside the object (object pixels of the backdrop's colour) are
filled. Larger holes are kept: a cup's handle shows the backdrop through it.

The rest of the pipeline (silhouette-aware sampling, size normalization, the extent
channel, the eigenspace) assumes one constant background, black by default:
:func:`set_background` puts it under every view, so the backdrop does not enter the
eigenspace and synthesized views, warped from views already masked, carry the same.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.check import check_finite, check_float_tensor, check_int, check_number, check_positive
from torch_eigview.io.foreground import estimate_foreground

__all__ = ["BackgroundModel", "background_rule", "border_pixels", "check_masks", "set_background"]


def check_masks(masks: object, images: torch.Tensor, name: str = "masks") -> torch.Tensor:
    """``masks`` checked against ``images`` (B, C, H, W): (B, 1, H, W) bool, no mask empty.

    Raises:
        TypeError: ``masks`` is not a bool tensor.
        ValueError: its shape is not (B, 1, H, W), or a mask is all background.
    """
    if not isinstance(masks, torch.Tensor) or masks.dtype != torch.bool:
        what = f"tensor of dtype {masks.dtype}" if isinstance(masks, torch.Tensor) else type(masks).__name__
        raise TypeError(f"{name} must be a bool tensor (True on the object), got a {what}")
    b, _, h, w = images.shape
    if tuple(masks.shape) != (b, 1, h, w):
        raise ValueError(
            f"{name} must have shape (B, 1, H, W) = {(b, 1, h, w)} to match the images, "
            f"got {tuple(masks.shape)}"
        )
    empty = (~masks.flatten(1).any(dim=1)).nonzero().flatten().tolist()
    if empty:
        raise ValueError(
            f"{name}[{empty[0]}] is all background (no True pixel; {len(empty)} such mask(s)): "
            "a view must show its object"
        )
    return masks


def _check_images(images: object) -> torch.Tensor:
    images = check_float_tensor(images, "images")
    if images.ndim != 4:
        raise ValueError(f"images must have shape (B, C, H, W), got shape {tuple(images.shape)}")
    check_finite(images, "images")
    return images


def set_background(images: torch.Tensor, masks: torch.Tensor, value: float = 0.0) -> torch.Tensor:
    """``images`` with every background pixel set to ``value`` (all channels).

    Args:
        images: (B, C, H, W) views.
        masks: (B, 1, H, W) bool, True on the object.
        value: the constant background intensity.

    Returns:
        (B, C, H, W) views; the object's pixels are the input's, unchanged.

    Example:
        >>> x = torch.full((1, 3, 2, 2), 0.5)
        >>> m = torch.tensor([[[[True, False], [False, False]]]])
        >>> set_background(x, m)[0, 0].tolist()
        [[0.5, 0.0], [0.0, 0.0]]
    """
    images = _check_images(images)
    masks = check_masks(masks, images)
    value = check_number(value, "value")
    if not math.isfinite(value):
        raise ValueError(f"value={value!r} must be a finite intensity")
    return torch.where(masks, images, images.new_tensor(value))


def border_pixels(images: torch.Tensor, width: int) -> torch.Tensor:
    """The pixels of each image's border of ``width`` pixels: (B, M, C), M = H·W − (H−2w)(W−2w)."""
    _, c, h, w = images.shape
    ring = torch.ones(h, w, dtype=torch.bool, device=images.device)
    ring[width : h - width, width : w - width] = False
    return images.permute(0, 2, 3, 1)[:, ring].reshape(images.shape[0], -1, c)


@dataclass(frozen=True)
class BackgroundModel:
    """How the foreground of a view is found and what its background becomes.

    Args:
        background: the background colour, one value per channel (e.g. ``(0.2, 0.4, 0.6)``),
            or None to estimate the colours from each image's border.
        tolerance: the largest distance (Euclidean over the channels, intensities in
            [0, 1]) from a background colour that is still background, or None for one
            from the border's spread.
        border: width in pixels of the border the colours and tolerances are taken from.
        max_colours: how many background colours the border may hold (backdrop and
            table: 2); used when ``background`` is None.
        min_fraction: foreground components and background holes smaller than this
            fraction of the image are flipped (0 keeps the raw mask).
        fill: the constant every background pixel is set to, or None to keep the background.

    Example:
        >>> x = torch.zeros(1, 3, 8, 8)
        >>> x[..., 2:6, 3:6] = 0.8
        >>> BackgroundModel().masks(x)[0, 0].sum().item()
        12
    """

    background: Sequence[float] | None = None
    tolerance: float | None = None
    border: int = 2
    max_colours: int = 2
    min_fraction: float = 0.005
    fill: float | None = 0.0

    def __post_init__(self) -> None:
        if self.background is not None:
            if isinstance(self.background, str) or not isinstance(self.background, Sequence):
                raise TypeError(f"background must be a sequence of numbers or None, got {self.background!r}")
            values = tuple(check_number(v, "background") for v in self.background)
            if not values or not all(0.0 <= v <= 1.0 for v in values):
                raise ValueError(f"background={self.background!r} must hold one value in [0, 1] per channel")
            object.__setattr__(self, "background", values)
        if self.tolerance is not None:
            check_positive(self.tolerance, "tolerance")
        check_int(self.border, "border", minimum=1)
        check_int(self.max_colours, "max_colours", minimum=1)
        frac = check_number(self.min_fraction, "min_fraction")
        if not 0.0 <= frac < 1.0:
            raise ValueError(f"min_fraction={self.min_fraction!r} must lie in [0, 1)")
        if self.fill is not None and not math.isfinite(check_number(self.fill, "fill")):
            raise ValueError(f"fill={self.fill!r} must be a finite intensity or None")

    def masks(self, images: torch.Tensor, masks: torch.Tensor | None = None) -> torch.Tensor:
        """The foreground masks of ``images``: ``masks`` when given (checked), else estimated.

        Args:
            images: (B, C, H, W) views in [0, 1].
            masks: optional (B, 1, H, W) bool masks, True on the object.

        Returns:
            (B, 1, H, W) bool, True on the object.

        Raises:
            ValueError: a given mask has another size or is all background; the
                background colour leaves no object in an image.
        """
        images = _check_images(images)
        if masks is not None:
            return check_masks(masks, images)
        b, c, h, w = images.shape
        if self.background is not None and len(self.background) != c:
            raise ValueError(
                f"background={self.background!r} must hold C={c} values, one per channel of images"
            )
        if min(h, w) == 0:
            raise ValueError(f"images have no pixels to tell their foreground from: (H, W)=({h}, {w})")
        if 2 * self.border >= min(h, w):
            raise ValueError(
                f"border={self.border} must be less than half the image side min(H, W)={min(h, w)}"
            )
        out = torch.zeros(b, 1, h, w, dtype=torch.bool)
        # One numpy rule for this and the torch-free eigview predict (io.foreground).
        for i, image in enumerate(images.detach().float().cpu().numpy()):
            mask = estimate_foreground(
                image,
                self.background,
                self.tolerance,
                border=self.border,
                max_colours=self.max_colours,
                min_fraction=self.min_fraction,
                where=f"images[{i}]",
            )
            out[i, 0] = torch.from_numpy(mask)
        return out.to(images.device)

    def apply(
        self, images: torch.Tensor, masks: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The views with their background set to ``fill`` (kept when None), and their masks.

        Args:
            images: (B, C, H, W) views in [0, 1].
            masks: optional (B, 1, H, W) bool masks; estimated when None.

        Returns:
            ``(views, masks)``: (B, C, H, W) and (B, 1, H, W) bool.
        """
        fg = self.masks(images, masks)
        if self.fill is None:
            return images, fg
        return set_background(images, fg, self.fill), fg


def background_rule(
    background: str, colour: tuple[float, ...] | None = None, tolerance: float | None = None
) -> BackgroundModel | None:
    """The :class:`BackgroundModel` of a background rule, as ``--background`` and a model's
    :class:`~torch_eigview.io.preprocessing.Preprocessing` record name it (``"keep"``,
    ``"auto"`` or ``"colour"`` with its colour and tolerance, in [0, 1]); None for
    ``"keep"``, which leaves the pixels as read.

    Example:
        >>> background_rule("keep") is None, background_rule("auto").background
        (True, None)
    """
    if background == "keep":
        return None
    return BackgroundModel(background=colour, tolerance=tolerance)
