"""Dense horizontal correspondences between two seed views.

Convention: images are (C, H, W); x is the column, y the row; pixel centres at integers.
For the orthographic camera rotating about the vertical axis a point keeps its row, so
a correspondence is a horizontal disparity: ``x2 = x1 + disparity_12[y, x1]`` maps a
pixel of view 1 to view 2, and ``x1 = x2 + disparity_21[y, x2]`` the other way. A pixel
is valid when the two maps agree (forward–backward consistency). Pixels of one view that
the other does not see (occlusions) are meant to fail that check; a regularized flow
(TV-L1) smooths across narrow occlusions, so only part of them do, and the warp's
z-buffer and two-view blend handle the rest.
"""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from torch.utils.data._utils.collate import default_collate_fn_map

from torch_eigview.check import check_finite, check_float_tensor, check_ndim, check_positive
from torch_eigview.geometry.row_maps import fill_row_holes, invert_row_map

__all__ = [
    "Correspondence",
    "check_correspondence",
    "correspondence_from_disparity",
]


@dataclass(frozen=True)
class Correspondence:
    """Horizontal correspondences between view 1 and view 2, both directions.

    Attributes:
        disparity_12: (B, H, W), ``x2 = x1 + disparity_12``.
        disparity_21: (B, H, W), ``x1 = x2 + disparity_21``.
        valid_12: (B, H, W) bool, view-1 pixels whose match is trusted.
        valid_21: (B, H, W) bool, view-2 pixels whose match is trusted.
        vertical_12: (B, H, W) ``y2 - y1`` measured by a 2D flow, or None. The
            orthographic model does not use it; :func:`torch_eigview.geometry.pose.estimate_elevation`
            measures a tilted camera from it.
        vertical_21: (B, H, W) ``y1 - y2`` of view-2 pixels, or None (used by the
            perspective camera, whose points move in both coordinates).
    """

    disparity_12: torch.Tensor
    disparity_21: torch.Tensor
    valid_12: torch.Tensor
    valid_21: torch.Tensor
    vertical_12: torch.Tensor | None = None
    vertical_21: torch.Tensor | None = None

    @property
    def shape(self) -> tuple[int, int, int]:
        """(B, H, W)."""
        b, h, w = self.disparity_12.shape
        return b, h, w

    def __len__(self) -> int:
        """B, the number of view pairs (a ``Dataset`` or ``Sampler`` sizes itself by it)."""
        return self.disparity_12.shape[0]

    def __iter__(self) -> Iterator[Correspondence]:
        """The view pairs one by one, each a correspondence of B = 1 (``self[i]``)."""
        return (self[i] for i in range(len(self)))

    def _map(self, fn: Callable[[torch.Tensor], torch.Tensor]) -> Correspondence:
        """The correspondence with ``fn`` applied to every tensor (None stays None)."""

        def optional(t: torch.Tensor | None) -> torch.Tensor | None:
            return None if t is None else fn(t)

        return Correspondence(
            fn(self.disparity_12),
            fn(self.disparity_21),
            fn(self.valid_12),
            fn(self.valid_21),
            optional(self.vertical_12),
            optional(self.vertical_21),
        )

    def to(
        self, device: torch.device | str | None = None, dtype: torch.dtype | None = None
    ) -> Correspondence:
        """Moves the disparities (and masks) to ``device``; ``dtype`` applies to disparities only."""
        return self._map(
            lambda t: t.to(device=device) if t.dtype == torch.bool else t.to(device=device, dtype=dtype)
        )

    def pin_memory(self) -> Correspondence:
        """The correspondence in page-locked memory (``DataLoader(pin_memory=True)`` calls it)."""
        return self._map(torch.Tensor.pin_memory)

    def __getitem__(self, index: int | slice | Sequence[int] | torch.Tensor) -> Correspondence:
        """The view pairs selected by ``index`` along B, as a correspondence.

        An integer keeps the batch dimension (``corr[i]`` has B = 1, like ``corr[i:i + 1]``):
        a correspondence is always (B, H, W), and :meth:`collate` concatenates such items
        back into a batch.

        Args:
            index: an int, a slice, a sequence of ints, a (B,) bool tensor or a (K,)
                integer tensor.

        Returns:
            A :class:`Correspondence` of shape (K, H, W) sharing storage where torch's
            indexing does (ints and slices).

        Example:
            >>> corr = correspondence_from_disparity(torch.zeros(4, 2, 3))
            >>> corr[1].shape, corr[1:3].shape, corr[torch.tensor([True, False, True, True])].shape
            ((1, 2, 3), (2, 2, 3), (3, 2, 3))
        """
        selector = _batch_selector(index, len(self))
        return self._map(
            lambda t: t[selector.to(t.device) if isinstance(selector, torch.Tensor) else selector]
        )

    @classmethod
    def collate(cls, items: Sequence[Correspondence]) -> Correspondence:
        """Concatenates correspondences along B: the inverse of indexing.

        Registered with :func:`torch.utils.data.default_collate`, so a ``DataLoader`` over
        samples that hold ``corr[i]`` batches them without a custom ``collate_fn``.

        Args:
            items: correspondences of shapes (B_i, H, W), all of one H, W, dtype and device,
                either all with the vertical flows or all without.

        Returns:
            A :class:`Correspondence` of shape (sum B_i, H, W).

        Example:
            >>> corr = correspondence_from_disparity(torch.zeros(3, 2, 4))
            >>> Correspondence.collate([corr[2], corr[0]]).shape
            (2, 2, 4)
        """
        if isinstance(items, Correspondence) or not isinstance(items, Sequence) or not items:
            raise ValueError(f"items must be a non-empty sequence of Correspondence, got {items!r:.80}")
        for i, item in enumerate(items):
            if not isinstance(item, Correspondence):
                raise TypeError(f"items[{i}] must be a Correspondence, got {type(item).__name__}")
            if item.shape[1:] != items[0].shape[1:]:
                raise ValueError(
                    f"items[{i}] has (H, W) = {item.shape[1:]}, items[0] has {items[0].shape[1:]}: "
                    "all correspondences of a batch must have one image size"
                )
        fields: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            values = [getattr(item, f.name) for item in items]
            present = [v is not None for v in values]
            if any(present) and not all(present):
                i = present.index(not present[0])
                given, missing = ("set", "None") if present[0] else ("None", "set")
                raise ValueError(
                    f"items[{i}].{f.name} is {missing} but items[0].{f.name} is {given}: "
                    f"{f.name} must be given for all items or for none"
                )
            fields[f.name] = torch.cat(values) if all(present) else None
        return cls(**fields)


def _batch_selector(index: object, b: int) -> slice | torch.Tensor:
    """``index`` of :meth:`Correspondence.__getitem__` as a slice or a 1-D index tensor."""
    if isinstance(index, (bool, str, bytes)) or not isinstance(
        index, (numbers.Integral, slice, Sequence, torch.Tensor)
    ):
        raise TypeError(
            f"index must be an int, a slice, a sequence of ints or a tensor, got {type(index).__name__}"
        )
    if isinstance(index, numbers.Integral):
        if not -b <= int(index) < b:
            raise IndexError(f"index {index} is out of range for a correspondence of B = {b}")
        start = int(index) % b
        return slice(start, start + 1)
    if isinstance(index, slice):
        return index
    selector = index if isinstance(index, torch.Tensor) else torch.as_tensor(index, dtype=torch.long)
    if selector.dtype == torch.bool:
        if selector.shape != (b,):
            raise IndexError(f"a boolean index must have shape (B,) = ({b},), got {tuple(selector.shape)}")
    elif selector.is_floating_point() or selector.is_complex() or selector.ndim != 1:
        raise IndexError(
            f"a tensor index must be (B,) bool or (K,) integer, got {selector.dtype} of shape {tuple(selector.shape)}"
        )
    return selector


def _collate_correspondences(
    batch: Sequence[Correspondence], *, collate_fn_map: dict[type, Callable[..., object]] | None = None
) -> Correspondence:
    """:func:`torch.utils.data.default_collate`'s hook for :class:`Correspondence` items."""
    return Correspondence.collate(batch)


# torch.utils.data.default_collate dispatches on the element type through this map; its
# documentation names extending it in place as the way to teach it a custom type.
default_collate_fn_map[Correspondence] = _collate_correspondences


def _sample_rows(values: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Linear interpolation of ``values`` (B, H, W) along each row at columns ``x`` (B, H, W)."""
    w = values.shape[-1]
    xc = torch.nan_to_num(x, nan=-1.0).clamp(0, w - 1)
    x0 = xc.floor().long().clamp(max=w - 2) if w > 1 else xc.floor().long()
    t = xc - x0
    v0 = values.gather(-1, x0)
    v1 = values.gather(-1, (x0 + 1).clamp(max=w - 1))
    return v0 * (1 - t) + v1 * t


def _consistency(d_ab: torch.Tensor, d_ba: torch.Tensor, threshold: float) -> torch.Tensor:
    """Pixels of view a whose match in view b maps back to within ``threshold`` pixels."""
    w = d_ab.shape[-1]
    cols = torch.arange(w, dtype=d_ab.dtype, device=d_ab.device).expand_as(d_ab)
    x_b = cols + d_ab
    inside = (x_b >= 0) & (x_b <= w - 1)  # False for NaN too
    round_trip = d_ab + _sample_rows(d_ba, x_b)
    return inside & (round_trip.abs() <= threshold)


def check_correspondence(correspondence: object, name: str = "correspondence") -> Correspondence:
    """Checks that ``correspondence`` is a :class:`Correspondence` whose tensors agree in shape.

    Raises:
        TypeError: not a :class:`Correspondence` (e.g. None).
        ValueError: a mask or vertical flow whose shape is not the disparities' (B, H, W).
    """
    if not isinstance(correspondence, Correspondence):
        raise TypeError(
            f"{name} must be a Correspondence (from estimate_correspondence or correspondence_from_disparity), "
            f"got {type(correspondence).__name__}"
        )
    shape = tuple(correspondence.disparity_12.shape)
    for field in dataclasses.fields(correspondence):
        value = getattr(correspondence, field.name)
        if value is not None and tuple(value.shape) != shape:
            raise ValueError(
                f"{name}.{field.name} must have the shape of disparity_12 {shape}, got {tuple(value.shape)}"
            )
    return correspondence


def _check_mask(mask: object, name: str, shape: torch.Size) -> torch.Tensor:
    """A validity mask of ``shape`` (or (H, W) for a single pair) as bool."""
    if not isinstance(mask, torch.Tensor):
        raise TypeError(f"{name} must be a bool tensor of shape {tuple(shape)}, got {type(mask).__name__}")
    if tuple(mask.shape) not in (tuple(shape), tuple(shape[1:])):
        raise ValueError(f"{name} must have shape {tuple(shape)}, got {tuple(mask.shape)}")
    return mask.reshape(shape).bool()


def correspondence_from_disparity(
    disparity_12: torch.Tensor,
    disparity_21: torch.Tensor | None = None,
    *,
    valid_12: torch.Tensor | None = None,
    valid_21: torch.Tensor | None = None,
    threshold: float = 1.0,
) -> Correspondence:
    """Wraps caller-supplied disparities (for example exact ones) as a :class:`Correspondence`.

    Args:
        disparity_12: (H, W) or (B, H, W), ``x2 = x1 + disparity_12``.
        disparity_21: same shape, the reverse map; if omitted it is obtained by inverting
            ``disparity_12`` row by row (valid where the inverse is single-valued).
        valid_12, valid_21: optional masks; by default the forward–backward check with
            ``threshold`` pixels decides.
        threshold: forward–backward tolerance in pixels, a finite number > 0.

    Raises:
        TypeError: a disparity or mask is not a tensor (the disparities float).
        ValueError: shapes that differ, non-finite disparities, or a bad ``threshold``.
    """
    d12 = check_float_tensor(disparity_12, "disparity_12")
    check_ndim(d12, "disparity_12", (2, 3), "(H, W) or (B, H, W)")
    check_finite(d12, "disparity_12")
    if d12.ndim == 2:
        d12 = d12[None]
    if disparity_21 is None:
        d21 = _invert_disparity(d12)
    else:
        d21 = check_float_tensor(disparity_21, "disparity_21")
        d21 = d21[None] if d21.ndim == 2 else d21
        if d21.shape != d12.shape:
            raise ValueError(
                f"disparity_21 must have the shape of disparity_12 {tuple(d12.shape)}, got {tuple(d21.shape)}"
            )
        check_finite(d21, "disparity_21")
    threshold = check_positive(threshold, "threshold")
    v12 = (
        _consistency(d12, d21, threshold)
        if valid_12 is None
        else _check_mask(valid_12, "valid_12", d12.shape)
    )
    v21 = (
        _consistency(d21, d12, threshold)
        if valid_21 is None
        else _check_mask(valid_21, "valid_21", d12.shape)
    )
    return Correspondence(d12, d21, v12, v21)


def _invert_disparity(d12: torch.Tensor) -> torch.Tensor:
    """Reverse disparity by inverting x2(x1) = x1 + d12 along each row (nearest monotone piece)."""

    w = d12.shape[-1]
    cols = torch.arange(w, dtype=d12.dtype, device=d12.device)
    x2 = (cols + d12)[:, None]  # (B, 1, H, W)
    ok = torch.ones_like(d12, dtype=torch.bool)
    src, hit = invert_row_map(x2, ok, None)
    src = fill_row_holes(src, hit, cols.expand_as(src))
    return src[:, 0] - cols
