"""Semi-global matching along the epipolar lines of a turntable camera, in torch.

Convention: images are (B, C, H, W); x is the column, y the row, pixel centres at
integers; the rotation axis is the column ``center``. A pixel of view 1 at
``X = x1 - center`` with depth Z (pixels, towards the camera at the second view's
side) lands in view 2, α degrees further round, at (Sec. 3 of the paper, with the
tilted camera of :func:`~torch_eigview.geometry.pose.estimate_elevation`)::

    x2 - x1 = X (cos α - 1) + k,               k = Z sin α,
    y2 - y1 = sin(elevation) (X sin α + k tan(α / 2)),

both then scaled by ``1 + scale`` about the image centre and shifted vertically by
``shift`` where the data set size-normalizes each image.

So a pixel's candidate matches form a one-parameter family, its epipolar line: nearly
horizontal, shifted vertically in proportion to X. The matcher labels each pixel with
the integer k in ``[-K, K]``, ``K = ceil(depth |sin α|)``: its depth, not its disparity,
so equal labels of neighbours mean equal depth, which is what SGM's smoothness favours.
Per label it samples the other view (bilinear) at the epipolar point, takes a patch
cost, aggregates it along four paths with SGM's P1/P2 penalties, picks the best label
with a parabola for sub-pixel depth, and does all this in both directions at once
(view 2 is view 1 turned by −α). The left–right check of
:func:`~torch_eigview.geometry.correspondence.correspondence_from_disparity` marks
pixels whose two matches disagree (occluded in the other view, or ambiguous) invalid.

Where each line lies vertically (the elevation, unless given, and the rescaling and
shift of a data set that size-normalizes every image) is fitted once per pair from a
coarse 2-D search (:func:`_line_model`); the dense matching is then one-dimensional.
"""

from __future__ import annotations

import dataclasses
import math

import torch
import torch.nn.functional as F

import torch_eigview._tuning as _tuning
from torch_eigview.check import check_alpha, check_choice, check_int, check_number, check_view_pair
from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.geometry.sgm import aggregate, winner

__all__ = ["COSTS", "check_row_options", "epipolar_matches", "match_rows", "volume_size"]

COSTS = ("adgrad", "zncc")


def _features(gray: torch.Tensor, cost: str) -> torch.Tensor:
    """(N, F, H, W) per-pixel features sampled along the epipolar line."""
    if cost == "zncc":
        return gray[:, None]
    gx = F.pad(gray[:, None], (1, 1, 0, 0), mode="replicate").diff(dim=-1)
    gy = F.pad(gray[:, None], (0, 0, 1, 1), mode="replicate").diff(dim=-2)
    # Central differences: mean of the two one-sided ones.
    gx = 0.5 * (gx[..., 1:] + gx[..., :-1])
    gy = 0.5 * (gy[..., 1:, :] + gy[..., :-1, :])
    return torch.cat([gray[:, None], gx, gy], dim=1)


def _box(x: torch.Tensor, patch: int) -> torch.Tensor:
    """Mean over a ``patch`` x ``patch`` window of each (.., H, W) image, edges replicated."""
    shape = x.shape
    h, w = shape[-2:]
    r = patch // 2
    padded = F.pad(x.reshape(-1, 1, h, w), (r, r, r, r), mode="replicate")[:, 0]
    # Separable, as shifted sums: a row mean then a column mean, 2·patch additions per pixel
    # where a 2-D pooling window adds patch² of them.
    rows = padded[..., :w].clone()
    for i in range(1, patch):
        rows += padded[..., i : i + w]
    rows.div_(patch)  # a mean per pass, as avg_pool2d: the same values bit for bit
    out = rows[..., :h, :].clone()
    for i in range(1, patch):
        out += rows[..., i : i + h, :]
    return out.div_(patch).reshape(shape)


def _epipolar_grid(
    n_labels: int, h: int, w: int, angles: torch.Tensor, model: torch.Tensor, center: float
) -> torch.Tensor:
    """(N, L, H, W, 2) normalized (x, y) in the other view of every pixel and label k.

    Args:
        angles: (N,) α in radians of each pair (−α for the reverse direction).
        model: (N, 3) the line model (tilt, scale, shift) of :func:`_line_model`.
    """
    dev, dt = angles.device, angles.dtype
    k = (torch.arange(n_labels, device=dev, dtype=dt) - (n_labels - 1) // 2)[None, :, None, None]
    big_x = torch.arange(w, device=dev, dtype=dt) - center
    big_y = torch.arange(h, device=dev, dtype=dt)[:, None] - (h - 1) / 2
    a = angles[:, None, None, None]
    tilt, scale, shift = (m[:, None, None, None] for m in model.unbind(1))
    x2 = center + (1 + scale) * (big_x * torch.cos(a) + k)  # (N, L, 1, W)
    grid = torch.empty((*x2.shape[:2], h, w, 2), device=dev, dtype=dt)
    # align_corners=True: -1 and 1 are the centres of the first and last pixels.
    grid[..., 0] = 2 * x2 / max(w - 1, 1) - 1
    # y2 = (h - 1) / 2 + (1 + scale) (Y + tilt (X sin α + k tan(α / 2))) + shift, normalized:
    # in place on one (N, L, H, W) buffer, the same operations in the same order.
    y2 = torch.add(tilt * (big_x * torch.sin(a) + k * torch.tan(a / 2)), big_y)
    y2.mul_(1 + scale).add_((h - 1) / 2).add_(shift).mul_(2).div_(max(h - 1, 1))
    torch.sub(y2, 1, out=grid[..., 1])
    return grid


def _cost_volume(
    ref: torch.Tensor, other: torch.Tensor, grid: torch.Tensor, cost: str, patch: int
) -> torch.Tensor:
    """(N, L, H, W) patch cost of matching each ``ref`` pixel to ``other`` at ``grid``."""
    n, f, h, w = ref.shape
    n_labels = grid.shape[1]
    # A slice of labels per grid_sample call, its size the memory-for-speed trade of
    # _tuning.COST_CHUNK_CPU / COST_CHUNK: each label's cost is its own, so the volume is
    # the same bit for bit whatever the slicing.
    chunk = _tuning.COST_CHUNK_CPU if ref.device.type == "cpu" else _tuning.COST_CHUNK
    per_label = max(1, chunk // max(1, n * f * h * w))
    out = []
    for start in range(0, n_labels, per_label):
        g = grid[:, start : start + per_label]
        m = g.shape[1]
        warped = F.grid_sample(
            # Outside the other view is black, as a turntable image's background: a match
            # there costs what matching the background costs, and the left–right check
            # rejects it.
            other,
            g.reshape(n, m * h, w, 2),
            mode="bilinear",
            padding_mode="zeros",
            align_corners=True,
        ).reshape(n, f, m, h, w)
        out.append(_patch_cost(ref, warped, cost, patch))
    return torch.cat(out, dim=1)


def _patch_cost(ref: torch.Tensor, warped: torch.Tensor, cost: str, patch: int) -> torch.Tensor:
    """(N, m, H, W) cost of ``ref`` (N, F, H, W) against ``warped`` (N, F, m, H, W)."""
    if cost == "adgrad":
        # |ref - warped| in place in this call's own samples (no volume-sized temporaries).
        diff = warped.sub_(ref[:, :, None]).abs_()
        grads = diff[:, 1:].sum(dim=1)
        # Truncated so that a few outliers (occlusions, highlights) do not dominate a patch.
        return _box(diff[:, 0].clamp_(max=0.2).add_(grads.clamp_(max=0.2)), patch)
    a, b = ref[:, 0, None].expand_as(warped[:, 0]), warped[:, 0]
    ma, mb = _box(a, patch), _box(b, patch)
    va = (_box(a * a, patch) - ma * ma).clamp_min(0)
    vb = (_box(b * b, patch) - mb * mb).clamp_min(0)
    cov = _box(a * b, patch) - ma * mb
    # The variance floor makes flat patches (the background) cost 1 at every label: no
    # preference, so SGM fills them from their textured neighbours.
    eps = 1e-4
    return 1 - cov / torch.sqrt((va + eps) * (vb + eps))


def _line_model(
    ref: torch.Tensor,
    other: torch.Tensor,
    angles: torch.Tensor,
    depth: float,
    center: float,
    tilt: float | None,
) -> torch.Tensor:
    """(N, 3) per direction the vertical line model (tilt, scale, shift) by coarse 2-D matching.

    A turntable view's rows move by ``tilt (X sin α + k tan(α/2))``; a data set that
    size-normalizes each image (COIL's processed images) also rescales and shifts them,
    ``scale (y − c_y) + shift``. At quarter resolution every (label, vertical offset) is
    tried, each pixel keeps its best, and the three (two with a given ``tilt``) are
    fitted to the offsets of the textured pixels by iteratively reweighted (Cauchy)
    least squares.
    """
    f = 4
    n, _, h, w = ref.shape
    small = F.avg_pool2d(torch.cat([ref, other]), f)
    r, o = small.chunk(2)
    hs, ws = small.shape[-2:]
    cs = (center + 0.5) / f - 0.5
    sin_a = angles.abs().sin().max().item()
    n_labels = 2 * math.ceil((depth * sin_a + 0.2 * w / 2) / f) + 1
    reach = math.ceil((0.5 * (w / 2) * (sin_a + 1 - math.cos(math.asin(sin_a))) + 0.2 * h / 2) / f)
    # Every vertical offset v at once: one cost volume of (2·reach + 1)·L labels, then per
    # pixel the best label of each offset and the best offset (the first of equal ones).
    shift = torch.zeros(n, 3, device=ref.device, dtype=ref.dtype)
    grids = []
    for v in range(-reach, reach + 1):
        shift[:, 2] = v
        grids.append(_epipolar_grid(n_labels, hs, ws, angles, shift, cs))
    volume = _cost_volume(r, o, torch.cat(grids, dim=1), "adgrad", 3).view(n, -1, n_labels, hs, ws)
    c_v, l_v = volume.min(dim=2)  # (N, V, hs, ws)
    best_v = c_v.argmin(dim=1, keepdim=True)
    label = l_v.gather(1, best_v)[:, 0].to(ref.dtype)
    dy = (best_v[:, 0] - reach).to(ref.dtype)
    k = label - (n_labels - 1) // 2
    big_x = torch.arange(ws, device=ref.device, dtype=ref.dtype) - cs
    big_y = (torch.arange(hs, device=ref.device, dtype=ref.dtype)[:, None] - (hs - 1) / 2).expand(hs, ws)
    a = angles[:, None, None]
    basis = [big_x * torch.sin(a) + k * torch.tan(a / 2), big_y.expand_as(k), torch.ones_like(k)]
    target = dy
    if tilt is not None:
        target = dy - tilt * basis[0]
        basis = basis[1:]
    textured = r[:, 1:].abs().sum(dim=1) > 0.01
    # The reweighted fits in float64 from elementwise sums (a p x p system per direction):
    # BLAS's float32 least squares varied in the last bits from run to run (it depends on
    # the buffers' alignment), and the lines, labels and matches with them.
    design = torch.stack(basis, dim=-1).reshape(n, -1, len(basis)).double()
    y = target.reshape(n, -1, 1).double()
    textured_w = textured.reshape(n, -1, 1).double()
    weight = textured_w
    for _ in range(6):
        wd = design * weight
        gram = (wd[:, :, :, None] * design[:, :, None, :]).sum(dim=1)
        sol = torch.linalg.lstsq(gram, (wd * y).sum(dim=1)[..., None]).solution
        res = ((design * sol[:, None, :, 0]).sum(dim=-1, keepdim=True) - y).abs()
        weight = textured_w / (1 + res.square())
    sol = sol.to(ref.dtype)
    sol = sol[..., 0]
    if tilt is not None:
        sol = torch.cat([torch.full_like(sol[:, :1], tilt), sol], dim=1)
    return sol * torch.tensor([1.0, 1.0, f], device=sol.device, dtype=sol.dtype)


def _check_views(view1: object, view2: object) -> tuple[torch.Tensor, torch.Tensor]:
    """The two views as finite float (B, C, H, W) tensors of one shape."""
    v1, v2 = check_view_pair(view1, view2)
    if min(v1.shape[-2:]) < 4:
        raise ValueError(
            f"view1 must be at least 4x4 pixels (the line model is searched at quarter resolution), "
            f"got H={v1.shape[-2]}, W={v1.shape[-1]}"
        )
    return v1, v2


def _tilt(elevation: object) -> float | None:
    """The sine of a given elevation in degrees, or None for ``"auto"``."""
    if isinstance(elevation, str):
        if elevation != "auto":
            raise ValueError(f"elevation must be a number of degrees or 'auto', got {elevation!r}")
        return None
    return math.sin(math.radians(check_number(elevation, "elevation")))


def _matches(
    k: torch.Tensor, model: torch.Tensor, angles: torch.Tensor, center: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Disparity ``x2 − x1`` and vertical flow ``y2 − y1`` (N, H, W) of labels ``k`` (N, H, W)."""
    _, h, w = k.shape
    big_x = torch.arange(w, device=k.device, dtype=k.dtype) - center
    big_y = torch.arange(h, device=k.device, dtype=k.dtype)[:, None] - (h - 1) / 2
    a = angles[:, None, None]
    tilt, scale, shift = (m[:, None, None] for m in model.unbind(1))
    disparity = (1 + scale) * (big_x * torch.cos(a) + k) - big_x
    vertical = (1 + scale) * (big_y + tilt * (big_x * torch.sin(a) + k * torch.tan(a / 2))) + shift - big_y
    return disparity, vertical


def match_rows(
    view1: torch.Tensor,
    view2: torch.Tensor,
    alpha: float,
    *,
    center: float | None = None,
    elevation: float | str = "auto",
    depth: float | None = None,
    cost: str = "adgrad",
    patch: int = 5,
    p1: float = 0.01,
    p2: float = 0.1,
    threshold: float = 1.0,
) -> Correspondence:
    """Dense correspondences of two turntable views by semi-global matching along rows.

    Args:
        view1: (C, H, W) or (B, C, H, W) first seed view (channels averaged to gray).
        view2: same shape, the view turned by ``alpha``.
        alpha: angle from view 1 to view 2 in degrees (not a multiple of 180).
        center: column of the rotation axis, default ``(W - 1) / 2``.
        elevation: camera elevation in degrees, or ``"auto"`` to find it by matching.
        depth: largest ``|Z|`` in pixels searched, default ``W / 2``; with α it sets the
            label range ``K = ceil(depth |sin α|)``.
        cost: ``"adgrad"`` (truncated absolute difference of intensity and gradient,
            averaged over the patch) or ``"zncc"`` (1 − zero-mean normalized
            cross-correlation of the patch).
        patch: odd side of the cost's square patch.
        p1: SGM penalty for a one-label change between neighbours.
        p2: SGM penalty for a larger change (a depth discontinuity).
        threshold: left–right tolerance in pixels for the validity masks.

    Returns:
        A :class:`~torch_eigview.geometry.correspondence.Correspondence` (B, H, W) on
        the device and dtype of ``view1``, with the vertical components of the
        epipolar matches in ``vertical_12`` and ``vertical_21``.

    Example:
        >>> tex = torch.rand(1, 1, 24, 32, generator=torch.Generator().manual_seed(0))
        >>> corr = match_rows(tex, tex, 10.0, elevation=0.0, depth=8.0)
        >>> corr.shape, corr.disparity_12.abs().max().item() < 4
        ((1, 24, 32), True)
    """
    v1, v2 = _check_views(view1, view2)
    alpha, cost, patch, tilt = check_row_options(
        alpha, center, elevation, depth, cost, patch, p1, p2, threshold
    )
    b, _, h, w = v1.shape
    c = (w - 1) / 2 if center is None else float(center)
    if b == 0:
        empty = v1.new_empty(0, h, w)
        return Correspondence(empty, empty, empty.bool(), empty.bool(), empty, empty)
    reach = w / 2 if depth is None else float(depth)
    # Float32 throughout: the costs need no more, and it is what a GPU runs fast. The
    # matches are not differentiable (the aggregation writes in place): the views enter detached.
    with torch.no_grad():
        gray = torch.cat([v1, v2]).detach().mean(dim=1).float()
        disparity, vertical = epipolar_matches(gray, alpha, c, reach, tilt, cost, patch, p1, p2)
    disparity, vertical = disparity.to(v1.dtype), vertical.to(v1.dtype)
    corr = correspondence_from_disparity(disparity[:b], disparity[b:], threshold=threshold)
    return dataclasses.replace(corr, vertical_12=vertical[:b], vertical_21=vertical[b:])


def check_row_options(
    alpha: object,
    center: object = None,
    elevation: object = "auto",
    depth: object = None,
    cost: object = "adgrad",
    patch: object = 5,
    p1: object = 0.01,
    p2: object = 0.1,
    threshold: object = 1.0,
) -> tuple[float, str, int, float | None]:
    """Validates :func:`match_rows`'s arguments other than the views.

    Returns:
        ``(alpha, cost, patch, tilt)``: the checked angle, cost and patch, and the sine of
        a given elevation (None for ``"auto"``).
    """
    alpha = check_alpha(alpha)  # type: ignore[arg-type]
    cost = check_choice(cost, "cost", COSTS)
    patch = check_int(patch, "patch", minimum=1)
    if patch % 2 == 0:
        raise ValueError(f"patch={patch} must be odd")
    for name, value in (("p1", p1), ("p2", p2), ("threshold", threshold), ("depth", depth or 1.0)):
        if not check_number(value, name) > 0:
            raise ValueError(f"{name}={value} must be positive")
    if center is not None:
        check_number(center, "center")
    return alpha, cost, patch, _tilt(elevation)


def volume_size(height: int, width: int, alpha: float, depth: float | None = None) -> int:
    """Elements of the cost volume :func:`match_rows` builds per view and direction for
    (H, W) views ``alpha`` degrees apart, ``depth`` its largest ``|Z|`` (default ``W / 2``):
    the labels ``2 ceil(depth |sin α|) + 1`` times the pixels. The matcher's memory is a few
    such volumes per direction; its callers size their batches by it."""
    reach = width / 2 if depth is None else float(depth)
    return (2 * math.ceil(reach * abs(math.sin(math.radians(alpha)))) + 1) * height * width


def epipolar_matches(
    gray: torch.Tensor,
    alpha: float,
    c: float,
    reach: float,
    tilt: float | None,
    cost: str,
    patch: int,
    p1: float,
    p2: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`match_rows`'s matches before the left–right check, for trusted arguments
    (:func:`check_row_options`'s; ``c`` the axis column, ``reach`` the largest ``|Z|``).

    Args:
        gray: (2B, H, W) float32 grayscale views, the B first views then the B second ones,
            at least 4 × 4.

    Returns:
        ``(disparity, vertical)``, each (2B, H, W) float32: view 1's pixels towards view 2,
        then view 2's towards view 1.
    """
    b = gray.shape[0] // 2
    h, w = gray.shape[-2:]
    feats = _features(gray, "adgrad")
    ref = feats if cost == "adgrad" else _features(gray, cost)
    rad = math.radians(alpha)
    angles = torch.tensor([rad] * b + [-rad] * b, device=gray.device)
    model = _line_model(feats, torch.cat([feats[b:], feats[:b]]), angles, reach, c, tilt)
    n_labels = 2 * math.ceil(reach * abs(math.sin(rad))) + 1
    grid = _epipolar_grid(n_labels, h, w, angles, model, c)
    volume = _cost_volume(ref, torch.cat([ref[b:], ref[:b]]), grid, cost, patch)
    return _matches(winner(aggregate(volume, p1, p2)), model, angles, c)
