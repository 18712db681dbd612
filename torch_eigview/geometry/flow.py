"""Dense correspondences between two seed views: TV-L1 optical flow (in torch, or scikit-image's),
scikit-image's ILK flow, the row matcher, or the row matcher's matches refined by TV-L1.

:func:`estimate_correspondence` estimates both directions (view 1 → 2 and 2 → 1) and
keeps the horizontal disparity with a forward–backward validity mask
(:func:`~torch_eigview.geometry.correspondence.correspondence_from_disparity`) and the
vertical flow, which the tilt estimate uses.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from torch_eigview.check import check_finite, check_float_tensor, check_ndim, check_positive
from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.geometry.guided_flow import guided_tvl1
from torch_eigview.geometry.row_matcher import match_rows
from torch_eigview.geometry.tvl1 import check_range, diverged, tvl1_flow

__all__ = ["METHODS", "estimate_correspondence"]

#: The correspondence methods of :func:`estimate_correspondence`.
METHODS = ("tvl1", "tvl1-skimage", "ilk", "rows", "guided")


def _to_gray_numpy(view: torch.Tensor) -> np.ndarray:
    return view.detach().to("cpu", torch.float64).mean(dim=0).numpy()


def estimate_correspondence(
    view1: torch.Tensor,
    view2: torch.Tensor,
    *,
    method: str = "tvl1",
    threshold: float = 1.0,
    **flow_kwargs: object,
) -> Correspondence:
    """Dense correspondences from optical flow (or the row matcher) and a consistency mask.

    The flow is estimated in both directions (view 1 → 2 and 2 → 1) on the grayscale
    images; its horizontal component is the disparity, as the orthographic rotation about
    the vertical axis moves points along rows, and its vertical one is kept for the tilt
    estimate.

    Args:
        view1: (C, H, W) or (B, C, H, W) image of the first seed view.
        view2: same shape, the second seed view.
        method: ``"tvl1"`` (:func:`~torch_eigview.geometry.tvl1.tvl1_flow`: TV-L1 in torch,
            every pair and both directions in one batch, on the views' device),
            ``"tvl1-skimage"`` (:func:`skimage.registration.optical_flow_tvl1`, the same
            algorithm pair by pair on the CPU: the reference), ``"ilk"``
            (:func:`skimage.registration.optical_flow_ilk`), ``"rows"`` (semi-global
            matching along the turntable's epipolar lines in torch,
            :func:`~torch_eigview.geometry.row_matcher.match_rows`) or ``"guided"`` (the
            row matcher's matches refined by TV-L1,
            :func:`~torch_eigview.geometry.guided_flow.guided_tvl1`: views far apart in
            angle); the last two need ``alpha`` among ``flow_kwargs``.
        threshold: forward–backward tolerance in pixels for the validity masks.
        **flow_kwargs: passed to the flow function (TV-L1's ``num_warp``, ``num_iter``, …).

    Returns:
        A :class:`Correspondence` of shape (B, H, W) on the device and dtype of ``view1``;
        B = 0 gives an empty one. Views one pixel high are matched along their one row.

    Raises:
        TypeError: a view is not a float tensor, or ``method`` not a str.
        ValueError: shapes that differ, are empty or narrower than 2 pixels, non-finite views,
            an unknown ``method``, a ``threshold`` that is not a finite number > 0, ``"rows"``
            or ``"guided"`` without ``alpha``, or a flow that diverges (views far outside
            image intensities).
    """
    v1 = check_float_tensor(view1, "view1")
    v2 = check_float_tensor(view2, "view2")
    check_ndim(v1, "view1", (3, 4), "(C, H, W) or (B, C, H, W)")
    if v2.shape != v1.shape:
        raise ValueError(f"view2 must have the shape of view1 {tuple(v1.shape)}, got {tuple(v2.shape)}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    threshold = check_positive(threshold, "threshold")
    if method in ("rows", "guided") and "alpha" not in flow_kwargs:
        raise ValueError(
            f"method={method!r} searches the epipolar lines of a rotation: pass alpha, the angle from "
            f"view1 to view2 in degrees (estimate_correspondence(..., method={method!r}, alpha=10.0))"
        )
    if v1.shape[-3] < 1:
        raise ValueError(f"view1 must have at least one channel, got shape {tuple(v1.shape)}")
    if v1.shape[-2] < 1 or v1.shape[-1] < 2:
        raise ValueError(
            f"view1 must be at least 2x2 pixels, or one row of 2 pixels or more (the flow takes image "
            f"gradients), got H={v1.shape[-2]}, W={v1.shape[-1]}"
        )
    if v1.shape[-2] == 1 and method != "rows":
        if method == "ilk":
            # Its per-pixel 2x2 system is singular without a vertical gradient: the flow would be 0.
            raise ValueError(
                f"view1 is one pixel high (H=1, W={v1.shape[-1]}): method='ilk' needs 2 rows or more, "
                f"use method='tvl1'"
            )
        return _one_row(v1, v2, method, threshold, flow_kwargs)
    if method == "rows":
        return match_rows(v1, v2, threshold=threshold, **flow_kwargs)  # type: ignore[arg-type]
    if method == "guided":
        return guided_tvl1(v1, v2, threshold=threshold, **flow_kwargs)  # type: ignore[arg-type]
    if method == "tvl1":
        return _torch_tvl1(v1, v2, threshold, flow_kwargs)
    return _skimage_flow(v1, v2, method, threshold, flow_kwargs)


def _torch_tvl1(
    v1: torch.Tensor, v2: torch.Tensor, threshold: float, flow_kwargs: dict[str, object]
) -> Correspondence:
    """TV-L1 in torch: all pairs, both directions, one batch (float32, as scikit-image's)."""
    check_finite(v1, "view1")
    check_finite(v2, "view2")
    if v1.ndim == 3:
        v1, v2 = v1[None], v2[None]
    b = v1.shape[0]
    largest = check_range(v1, v2, "tvl1")
    # Grayscale as the reference path makes it (float64 mean, then scikit-image's float32),
    # where the device has float64 (not MPS).
    wide = torch.float64 if v1.device.type in ("cpu", "cuda") else torch.float32
    g1, g2 = (v.detach().to(wide).mean(dim=1).float() for v in (v1, v2))
    with torch.no_grad():
        flow = tvl1_flow(torch.cat([g1, g2]), torch.cat([g2, g1]), **flow_kwargs)  # type: ignore[arg-type]
    if not bool(torch.isfinite(flow).all()):
        raise diverged("tvl1", largest)
    flow = flow.to(v1.dtype)
    corr = correspondence_from_disparity(flow[:b, 1], flow[b:, 1], threshold=threshold)
    return dataclasses.replace(corr, vertical_12=flow[:b, 0], vertical_21=flow[b:, 0])


def _one_row(
    v1: torch.Tensor, v2: torch.Tensor, method: str, threshold: float, flow_kwargs: dict[str, object]
) -> Correspondence:
    """The correspondence of 1-pixel-high views: each matched as two identical rows.

    A flow takes vertical gradients, which one row does not have; two copies of it have
    zero vertical gradient, so the flow moves along the row only and both rows agree.
    """
    two1, two2 = (v.expand(*v.shape[:-2], 2, v.shape[-1]) for v in (v1, v2))
    corr = estimate_correspondence(two1, two2, method=method, threshold=threshold, **flow_kwargs)
    fields = {f.name: getattr(corr, f.name) for f in dataclasses.fields(corr)}
    return dataclasses.replace(corr, **{k: v[..., :1, :] for k, v in fields.items() if v is not None})


def _skimage_flow(
    v1: torch.Tensor, v2: torch.Tensor, method: str, threshold: float, flow_kwargs: dict[str, object]
) -> Correspondence:
    """scikit-image's TV-L1 (``"tvl1-skimage"``) or ILK flow in both directions, pair by pair,
    on the CPU."""
    view1 = v1
    check_finite(v1, "view1")
    check_finite(v2, "view2")
    if v1.ndim == 3:
        v1, v2 = v1[None], v2[None]
    if v1.shape[0] == 0:  # an empty batch of pairs has an empty correspondence
        empty = v1.new_zeros(0, *v1.shape[-2:])
        mask = torch.zeros(empty.shape, dtype=torch.bool, device=v1.device)
        return Correspondence(empty, empty.clone(), mask, mask.clone(), empty.clone(), empty.clone())
    # Imported here: scikit-image's registration pulls in scipy.ndimage, which the default
    # torch flow does not need (a few tenths of a second of every command's start).
    from skimage.registration import optical_flow_ilk, optical_flow_tvl1

    flow = optical_flow_tvl1 if method == "tvl1-skimage" else optical_flow_ilk
    d12, d21, v12, v21 = [], [], [], []
    # A diverging flow is reported below with its cause, not as numpy's RuntimeWarnings.
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for a, b in zip(v1, v2, strict=True):
            ga, gb = _to_gray_numpy(a), _to_gray_numpy(b)
            # skimage: moving(r + v, c + u) ~ reference(r, c), so u maps reference to moving.
            fwd = flow(ga, gb, **flow_kwargs)
            d12.append(fwd[1])
            v12.append(fwd[0])
            bwd = flow(gb, ga, **flow_kwargs)
            d21.append(bwd[1])
            v21.append(bwd[0])

    def tensor(arrays: list[np.ndarray]) -> torch.Tensor:
        return torch.as_tensor(np.stack(arrays), dtype=view1.dtype, device=view1.device)

    if not all(np.isfinite(f).all() for f in (*d12, *d21, *v12, *v21)):
        raise diverged(method, max(float(v1.abs().max()), float(v2.abs().max())))

    corr = correspondence_from_disparity(tensor(d12), tensor(d21), threshold=threshold)
    return dataclasses.replace(corr, vertical_12=tensor(v12), vertical_21=tensor(v21))
