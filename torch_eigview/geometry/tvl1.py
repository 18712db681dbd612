"""TV-L1 optical flow in torch, batched: scikit-image's ``optical_flow_tvl1`` on tensors.

The algorithm, step for step, is scikit-image's (Zach, Pock and Bischof 2007, with the
numerical scheme of Pérez, Meinhardt-Llopis and Facciolo 2013): a coarse-to-fine pyramid
(Gaussian smoothing, σ = 2/3, then halving with bilinear interpolation), at each level
``num_warp`` warps of the moving image, each followed by ``num_iter`` fixed-point steps of
the thresholded data term and two Chambolle projections per flow component. What differs
is that many image pairs run at once, as one (N, H, W) batch, on any device, and that the
whole loop is a few dozen tensor operations per step instead of per pair: on the CPU the
COIL-20 seed pairs of one experiment (40 directions) take one call.

Convention: images are (N, H, W) grayscale; the flow is (N, 2, H, W) with the row (y)
component first and the column (x) component second, scikit-image's order, and
``moving[r + v, c + u] ≈ reference[r, c]``. Pixel centres are at integers; the warp
samples with ``align_corners=True`` and edge padding (scikit-image's ``mode="edge"``).

Each pair stops at a level when its flow stops changing (scikit-image's ``tol``: the
squared change over one warp below ``tol · H · W``), independently of the rest of the
batch. scikit-image compares the flow at the end of a warp with the flow after the
warp's first data step (its arrays alias there); so does this port, so that both stop
after the same warp.

scikit-image stays the reference: ``tests/geometry/test_tvl1.py`` compares the pyramid,
the flow upsampling and the flow itself with it.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from torch_eigview.check import check_finite, check_float_tensor, check_int, check_ndim, check_positive

__all__ = ["check_range", "diverged", "max_magnitude", "tvl1_flow", "warp_by_flow"]

# scikit-image's pyramid: halve until the smaller side is at most 2 · 16, at most 10 levels.
_DOWNSCALE, _MIN_SIZE, _MAX_LEVELS = 2, 16, 10
_SIGMA = 2 * _DOWNSCALE / 6.0  # pyramid_reduce's smoothing
_REG_ITERS = 2  # Chambolle projections per fixed-point step


def _gaussian_kernel(dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """scipy.ndimage's 1-D Gaussian of σ = 2/3, truncated at 4σ (radius 3), normalized."""
    radius = int(4.0 * _SIGMA + 0.5)
    x = torch.arange(-radius, radius + 1, dtype=torch.float64)
    k = torch.exp(-0.5 * (x / _SIGMA) ** 2)
    return (k / k.sum()).to(dtype=dtype, device=device)


def _symmetric_index(n: int, radius: int, device: torch.device) -> torch.Tensor:
    """Indices of a length-``n`` axis padded by ``radius`` with scipy's ``"reflect"``
    (d c b a | a b c d | d c b a); ``n >= radius``."""
    i = torch.arange(-radius, n + radius, device=device)
    return torch.where(i < 0, -i - 1, torch.where(i >= n, 2 * n - 1 - i, i))


def _smooth(images: torch.Tensor) -> torch.Tensor:
    """(N, H, W) Gaussian smoothing as ``scipy.ndimage.gaussian_filter(mode="reflect")``.

    Separable, each pass a weighted sum of shifted slices of the padded images: 2·(2r + 1)
    multiply-adds per pixel in elementwise passes over whole planes, where a convolution
    kernel would have a single channel to spread its work over."""
    k = _gaussian_kernel(images.dtype, images.device).tolist()
    r = (len(k) - 1) // 2
    out = images
    for dim in (1, 2):
        n = out.shape[dim]
        padded = out.index_select(dim, _symmetric_index(n, r, out.device))
        acc = padded.narrow(dim, 0, n) * k[0]
        for i in range(1, len(k)):
            acc.add_(padded.narrow(dim, i, n), alpha=k[i])
        out = acc
    return out


def _reduce(images: torch.Tensor) -> torch.Tensor:
    """One pyramid level down: ``skimage.transform.pyramid_reduce(image, 2)`` on (N, H, W).

    Smoothing, then bilinear resampling to ``ceil(side / 2)`` with pixel areas aligned
    (scikit-image's ``resize``, ``ndimage.zoom(grid_mode=True)``): what
    ``interpolate(align_corners=False)`` computes."""
    h, w = images.shape[-2:]
    size = (math.ceil(h / _DOWNSCALE), math.ceil(w / _DOWNSCALE))
    smoothed = _smooth(images)
    return F.interpolate(smoothed[:, None], size=size, mode="bilinear", align_corners=False)[:, 0]


def _pyramid(images: torch.Tensor, min_size: int = _MIN_SIZE) -> list[torch.Tensor]:
    """(N, H, W) images from the coarsest level to the finest (scikit-image's ``_get_pyramid``)."""
    levels = [images]
    while len(levels) < _MAX_LEVELS and min(levels[-1].shape[-2:]) > _DOWNSCALE * min_size:
        levels.append(_reduce(levels[-1]))
    return levels[::-1]


def _nearest_index(n_in: int, n_out: int, device: torch.device) -> torch.Tensor:
    """The source index of each output index of ``ndimage.zoom(order=0)`` (corners aligned)."""
    if n_out == 1:
        return torch.zeros(1, dtype=torch.long, device=device)
    x = torch.arange(n_out, dtype=torch.float64, device=device) * ((n_in - 1) / (n_out - 1))
    return torch.floor(x + 0.5).long().clamp_(0, n_in - 1)


def _upsample_flow(flow: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    """(N, 2, h, w) flow at the next level's (H, W): nearest neighbour, values scaled by the
    size ratios (scikit-image's ``_resize_flow``)."""
    h, w = flow.shape[-2:]
    rows = _nearest_index(h, shape[0], flow.device)
    cols = _nearest_index(w, shape[1], flow.device)
    out = flow.index_select(2, rows).index_select(3, cols)
    scale = torch.tensor([shape[0] / h, shape[1] / w], dtype=flow.dtype, device=flow.device)
    return out * scale.view(1, 2, 1, 1)


def warp_by_flow(fields: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """(N, F, H, W) ``fields`` sampled bilinearly at (r + v, c + u) of a (N, 2, H, W) flow
    (rows first, as :func:`tvl1_flow` returns it), edge values outside."""
    h, w = fields.shape[-2:]
    rows = torch.arange(h, dtype=flow.dtype, device=flow.device).view(h, 1)
    cols = torch.arange(w, dtype=flow.dtype, device=flow.device)
    gx = (flow[:, 1] + cols) * (2.0 / max(w - 1, 1)) - 1
    gy = (flow[:, 0] + rows) * (2.0 / max(h - 1, 1)) - 1
    grid = torch.stack([gx, gy], dim=-1)
    return F.grid_sample(fields, grid, mode="bilinear", padding_mode="border", align_corners=True)


def _median3(flow: torch.Tensor) -> torch.Tensor:
    """(N, 2, H, W) flow through a 3 × 3 median per component, scipy's
    ``median_filter(size=[1, 3, 3], mode="reflect")`` (scikit-image's ``prefilter``)."""
    n, c, h, w = flow.shape
    rows = flow.index_select(2, _symmetric_index(h, 1, flow.device))
    padded = rows.index_select(3, _symmetric_index(w, 1, flow.device))
    patches = padded.unfold(2, 3, 1).unfold(3, 3, 1)  # (N, 2, H, W, 3, 3)
    return patches.reshape(n, c, h, w, 9).median(dim=-1).values


def _gradient(image: torch.Tensor) -> torch.Tensor:
    """``numpy.gradient`` of (N, H, W) along rows and columns: (N, 2, H, W), central
    differences inside, one-sided at the edges."""
    out = image.new_empty(image.shape[0], 2, *image.shape[1:])
    for axis, g in ((1, out[:, 0]), (2, out[:, 1])):
        n = image.shape[axis]
        f = image.movedim(axis, -1)
        d = g.movedim(axis, -1)
        if n > 2:
            torch.sub(f[..., 2:], f[..., :-2], out=d[..., 1:-1]).mul_(0.5)
        d[..., 0] = f[..., 1] - f[..., 0]
        d[..., -1] = f[..., -1] - f[..., -2]
    return out


def _level(
    reference: torch.Tensor,
    moving: torch.Tensor,
    flow: torch.Tensor,
    attachment: float,
    tightness: float,
    num_warp: int,
    num_iter: int,
    tol: float,
    prefilter: bool,
) -> torch.Tensor:
    """scikit-image's ``_tvl1`` at one pyramid level for (N, H, W) pairs; ``flow`` (N, 2, H, W)
    is the initial flow (not modified)."""
    n, h, w = reference.shape
    dt = 0.25  # 0.5 / ndim
    f0 = attachment * tightness
    f1 = dt / tightness
    tol_level = tol * h * w
    flow = flow.clone()
    # Both flow components at once (they do not interact in the regularization: half the
    # tensor calls of one component at a time, the same values). ``g`` holds each
    # component's differences along rows and columns; their last row / column stays 0.
    g = flow.new_zeros(n, 2, 2, h, w)
    proj = flow.new_zeros(n, 2, 2, h, w)  # the dual variable per flow component and axis
    active = torch.ones(n, dtype=torch.bool, device=flow.device)
    for _ in range(num_warp):
        if prefilter:
            flow = _median3(flow)
        warped = warp_by_flow(moving[:, None], flow)[:, 0]
        grad = _gradient(warped)
        ni = torch.addcmul(grad[:, 0] * grad[:, 0], grad[:, 1], grad[:, 1])
        ni = torch.where(ni == 0, 1.0, ni)
        gy, gx = grad[:, 0], grad[:, 1]
        rho_0 = warped - reference - gy * flow[:, 0] - gx * flow[:, 1]
        bound = f0 * ni  # the data step's threshold, fixed over the warp
        start = flow
        after_first_data = flow
        for it in range(num_iter):
            # Data term: the thresholding step of TV-L1.
            rho = torch.addcmul(torch.addcmul(rho_0, gy, flow[:, 0]), gx, flow[:, 1])
            step = torch.where(rho.abs() <= bound, rho / ni, f0 * torch.sign(rho))
            aux = torch.addcmul(flow, step[:, None], grad, value=-1)
            if it == 0:
                after_first_data = aux
            # Regularization: Chambolle's projection, twice, both components at once; the
            # first differences are aux's (the flow before the projection).
            flow = torch.empty_like(aux)
            current = aux
            for _ in range(_REG_ITERS):
                torch.diff(current, dim=2, out=g[:, :, 0, :-1])
                torch.diff(current, dim=3, out=g[:, :, 1, :, :-1])
                norm = torch.hypot(g[:, :, 0], g[:, :, 1]).mul_(f1).add_(1.0)
                proj.sub_(g, alpha=dt).div_(norm[:, :, None])
                # The flow plus the divergence of p (backward differences, p's last
                # row / column taken as 0 beyond the edge).
                torch.sub(aux, proj[:, :, 0], out=flow)
                flow.sub_(proj[:, :, 1])
                flow[:, :, 1:].add_(proj[:, :, 0, :-1])
                flow[:, :, :, 1:].add_(proj[:, :, 1, :, :-1])
                current = flow
        change = (after_first_data - flow).square().sum((1, 2, 3))
        flow = torch.where(active.view(n, 1, 1, 1), flow, start)
        active = active & ~(change < tol_level)
        if not bool(active.any()):
            break
    return flow


def diverged(method: str, largest: float) -> ValueError:
    """The error of a flow (this one or another) that came back with NaN or infinite values,
    ``largest`` the views' largest magnitude."""
    return ValueError(
        f"the {method} flow between view1 and view2 diverged (NaN or infinite flow): the views' values "
        f"(largest magnitude {largest:.3g}) must be image intensities, e.g. in [0, 1]"
    )


def check_range(v1: torch.Tensor, v2: torch.Tensor, method: str) -> float:
    """The views' largest magnitude (0 for empty views); raises the error of views whose
    values TV-L1's float32 squared gradients cannot take."""
    largest = max(float(v1.abs().max()), float(v2.abs().max())) if v1.numel() else 0.0
    if largest > max_magnitude(torch.float32):
        raise ValueError(
            f"the {method} flow between view1 and view2 cannot take values of magnitude {largest:.3g} (float32's "
            f"squared gradients overflow beyond {max_magnitude(torch.float32):.3g}): the views must be image "
            f"intensities, e.g. in [0, 1]"
        )
    return largest


def max_magnitude(dtype: torch.dtype) -> float:
    """The largest image value :func:`tvl1_flow` takes in ``dtype``: the squared image
    gradients (and their sums) must stay finite, else the data term silently vanishes."""
    return math.sqrt(torch.finfo(dtype).max) / 16


def tvl1_flow(
    reference: torch.Tensor,
    moving: torch.Tensor,
    *,
    attachment: float = 15.0,
    tightness: float = 0.3,
    num_warp: int = 5,
    num_iter: int = 10,
    tol: float = 1e-4,
    prefilter: bool = False,
    min_size: int = _MIN_SIZE,
) -> torch.Tensor:
    """TV-L1 optical flow of many image pairs at once (scikit-image's algorithm and defaults).

    Args:
        reference: (N, H, W) or (H, W) float grayscale images.
        moving: same shape, the images the flow points into.
        attachment: weight of the data term (smaller: smoother flow), > 0.
        tightness: coupling of the data and regularization terms, > 0.
        num_warp: warps of the moving image per pyramid level, >= 1.
        num_iter: fixed-point iterations per warp, >= 1.
        tol: a pair stops at a level when its flow changes by less than this per pixel
            (squared) over one warp, >= 0.
        prefilter: pass the flow through a 3 × 3 median before each warp.
        min_size: the pyramid halves the images while their smaller side exceeds twice
            this (scikit-image's fixed 16), >= 1; smaller values add coarser levels.

    Returns:
        (N, 2, H, W) (or (2, H, W)) flow in the images' dtype and device, rows first:
        ``moving[r + flow[0], c + flow[1]] ≈ reference[r, c]``. Not differentiable: the
        images enter detached (the solver writes its buffers in place).

    Raises:
        TypeError: the images are not float tensors.
        ValueError: shapes that differ or are smaller than 2 × 2, non-finite images or
            values beyond :func:`max_magnitude`, or bad parameters.

    Example:
        >>> y, x = torch.meshgrid(torch.arange(48.0), torch.arange(48.0), indexing="ij")
        >>> ref = torch.exp(-((x - 22) ** 2 + (y - 24) ** 2) / 60)  # a blob at column 22
        >>> mov = torch.exp(-((x - 24) ** 2 + (y - 24) ** 2) / 60)  # moved 2 to the right
        >>> round(tvl1_flow(ref, mov)[1, 20:28, 18:27].mean().item(), 1)
        2.0
    """
    ref = check_float_tensor(reference, "reference")
    mov = check_float_tensor(moving, "moving")
    check_ndim(ref, "reference", (2, 3), "(N, H, W) or (H, W)")
    if mov.shape != ref.shape:
        raise ValueError(
            f"moving must have the shape of reference {tuple(ref.shape)}, got {tuple(mov.shape)}"
        )
    if min(ref.shape[-2:]) < 2:
        raise ValueError(f"reference must be at least 2 x 2 pixels, got shape {tuple(ref.shape)}")
    check_finite(ref, "reference")
    check_finite(mov, "moving")
    for image, name in ((ref, "reference"), (mov, "moving")):
        largest = float(image.abs().max()) if image.numel() else 0.0
        if largest > max_magnitude(image.dtype):
            raise ValueError(
                f"{name} holds values of magnitude {largest:.3g}, beyond {max_magnitude(image.dtype):.3g} where "
                f"{image.dtype}'s squared gradients overflow: it must hold image intensities, e.g. in [0, 1]"
            )
    for value, name in ((attachment, "attachment"), (tightness, "tightness")):
        check_positive(value, name)
    check_positive(tol, "tol", allow_zero=True)
    num_warp = check_int(num_warp, "num_warp", minimum=1)
    num_iter = check_int(num_iter, "num_iter", minimum=1)
    min_size = check_int(min_size, "min_size", minimum=1)
    if not isinstance(prefilter, bool):
        raise TypeError(f"prefilter must be a bool, got {type(prefilter).__name__}")
    ref, mov = ref.detach(), mov.detach()
    single = ref.ndim == 2
    ref, mov = (ref[None], mov[None]) if single else (ref, mov)
    if ref.shape[0] == 0:
        return ref.new_zeros(0, 2, *ref.shape[1:])
    levels = list(zip(_pyramid(ref, min_size), _pyramid(mov, min_size), strict=True))
    flow = ref.new_zeros(ref.shape[0], 2, *levels[0][0].shape[-2:])
    for i, (r, m) in enumerate(levels):
        if i > 0:
            flow = _upsample_flow(flow, (r.shape[-2], r.shape[-1]))
        flow = _level(r, m, flow, attachment, tightness, num_warp, num_iter, tol, prefilter)
    return flow[0] if single else flow
