"""The two factors of A = G·C (Eqs. 3–6) as sparse COO tensors: seed matrices and coefficients.

Convention:
    Images are (C, H, W); x is the column, y the row; pixel centres at integers. A view
    is flattened row-major over (C, H, W), so row ``r = (c, j, l)`` of A is
    ``c·H·W + j·W + l``. For S seed views, G is (C·H·W, S·H·W·W): row ``(c, j, l)`` holds
    seed row ``I_s[c, j, :]`` in column block ``(s, j, l)``, i.e.
    ``G[(c, j, l), (s, j, l, k)] = I_s[c, j, k]`` with column index
    ``s·H·W·W + (j·W + l)·W + k``. Column t of C holds, at rows ``(s, j, l, k)``, the
    interpolation coefficients ``y_k`` of target pixel (j, l) of view t (Eq. 3's
    ``C_j^l``), with the blend weight of seed view s folded in; coefficients do not
    depend on the channel. Hence ``(G·C)[(c, j, l), t] = Σ_s Σ_k I_s[c, j, k] · y_k``.

    In the whole-image layout (2D warps, Sec. 4) G is (C·H·W, S·(H·W)²) with
    ``G[(c, p), (s, p, q)] = I_s[c, q]`` (column ``s·(H·W)² + p·H·W + q``) and C holds at
    rows ``(s, p, q)`` the 2D bilinear weights of grid sampling (four per target pixel).

C is filled either from target→source maps (``gather``: the tent weights kornia's
``remap`` applies) or from a forward map (``splat``: Eq. 4 as written);
:class:`~torch_eigview.warp.operator.SparseViewOperator` assembles them.
"""

from __future__ import annotations

import torch

from torch_eigview.warp.maps import _renormalize


def _seed_matrix(images: torch.Tensor) -> torch.Tensor:
    """G = [G_1 … G_S], (C·H·W, S·H·W·W), from seed images (S, C, H, W); zeros left out."""
    s, c, h, w = images.shape
    # Flat positions p over (c, j, l, s, k) are sorted by (row, column): G is built coalesced.
    values = images.permute(1, 2, 0, 3)[:, :, None].expand(c, h, w, s, w).reshape(-1)
    p = values.nonzero().squeeze(1)
    rows = p // (s * w)
    sk = p % (s * w)
    cols = (sk // w) * (h * w * w) + (rows % (h * w)) * w + sk % w
    return torch.sparse_coo_tensor(
        torch.stack([rows, cols]),
        values[p],
        (c * h * w, s * h * w * w),
        is_coalesced=True,
        check_invariants=False,
    )


def _sparse(
    rows: torch.Tensor, cols: torch.Tensor, values: torch.Tensor, size: tuple[int, int]
) -> torch.Tensor:
    return torch.sparse_coo_tensor(torch.stack([rows, cols]), values, size, check_invariants=False).coalesce()


def _silhouette_normalize(tent: torch.Tensor, inside: torch.Tensor, fg: torch.Tensor) -> torch.Tensor:
    """Tap weights (S, T, H, W, K) restricted to foreground taps and renormalized per
    target pixel over all taps of all sources; 0 where the foreground share is below 1/2
    (``NovelViewWarp.apply_maps`` with ``masks``). ``fg`` (S, T, H, W, K): the tap's mask."""
    tent = tent * (fg & inside).to(tent.dtype)
    return _renormalize(tent, tent.sum(dim=(0, -1), keepdim=True))


def _gather_coefficients(
    src_x: torch.Tensor, weight: torch.Tensor, masks: torch.Tensor | None = None
) -> torch.Tensor:
    """C (S·H·W·W, T) from target→source maps and blend weights, both (S, T, H, W), and
    optional (S, H, W) seed masks (silhouette-aware weights)."""
    s, t, h, w = src_x.shape
    dev = src_x.device
    use = weight != 0
    # Clamping keeps floor() in the int64 range; beyond [-1, W] no neighbour is inside.
    x = torch.where(use, src_x, 0.0).clamp(-2.0, w + 1.0)
    # The view sampler normalizes pixel columns to [-1, 1] as kornia's remap does, and
    # grid_sample maps them back; in float32 that round trip moves x by ~W·eps. Take the same round trip, so that C holds
    # the weights grid sampling actually applies, not the ones it would in exact arithmetic.
    x = ((2.0 / (w - 1)) * x - 1 + 1) * ((w - 1) / 2) if w > 1 else x
    k0 = x.floor()
    frac = x - k0
    k = torch.stack([k0, k0 + 1], dim=-1)  # (S, T, H, W, 2)
    # Eq. 4 from the target's side: 1 - |x - k| for the two neighbours k of x.
    tent = torch.stack([1 - frac, frac], dim=-1) * weight[..., None]
    inside = (k >= 0) & (k <= w - 1)
    if masks is not None:
        row_of = torch.arange(h, device=dev).view(1, 1, h, 1, 1) * w
        flat = masks.reshape(s, 1, h * w).expand(s, t, h * w)
        fg = flat.gather(2, (row_of + k.long().clamp(0, w - 1)).reshape(s, t, -1)).view_as(tent) != 0
        tent = _silhouette_normalize(tent, inside, fg)
    keep = use[..., None] & inside & (tent != 0)
    block = torch.arange(s, device=dev).view(s, 1, 1, 1, 1) * (h * w * w)
    jl = torch.arange(h * w, device=dev).view(1, 1, h, w, 1)
    rows = block + jl * w + k.long()
    cols = torch.arange(t, device=dev).view(1, t, 1, 1, 1).expand_as(rows)
    return _sparse(rows[keep], cols[keep], tent[keep], (s * h * w * w, t))


def _gather_coefficients_2d(
    src_x: torch.Tensor, src_y: torch.Tensor, weight: torch.Tensor, masks: torch.Tensor | None = None
) -> torch.Tensor:
    """C (S·(H·W)², T) of a 2D warp from maps and blend weights, all (S, T, H, W), and
    optional (S, H, W) seed masks (silhouette-aware weights).

    Four bilinear weights per target pixel p at its source position (x, y): rows
    ``(s, p, q)`` for the source pixels q = (y0 + dy, x0 + dx) inside the image.
    """
    s, t, h, w = src_x.shape
    dev = src_x.device
    n = h * w
    use = weight != 0
    # The sampler's pixel -> normalized -> pixel round trip (kornia's remap's), as in the row case.
    x = torch.where(use, src_x, 0.0).clamp(-2.0, w + 1.0)
    y = torch.where(use, src_y, 0.0).clamp(-2.0, h + 1.0)
    x = ((2.0 / (w - 1)) * x - 1 + 1) * ((w - 1) / 2) if w > 1 else x
    y = ((2.0 / (h - 1)) * y - 1 + 1) * ((h - 1) / 2) if h > 1 else y
    x0, y0 = x.floor(), y.floor()
    fx, fy = x - x0, y - y0
    xs = torch.stack([x0, x0 + 1, x0, x0 + 1], dim=-1)  # (S, T, H, W, 4)
    ys = torch.stack([y0, y0, y0 + 1, y0 + 1], dim=-1)
    tent = torch.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], dim=-1)
    tent = tent * weight[..., None]
    inside = (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    if masks is not None:
        q = ys.long().clamp(0, h - 1) * w + xs.long().clamp(0, w - 1)
        flat = masks.reshape(s, 1, n).expand(s, t, n)
        fg = flat.gather(2, q.reshape(s, t, -1)).view_as(tent) != 0
        tent = _silhouette_normalize(tent, inside, fg)
    keep = use[..., None] & inside & (tent != 0)
    block = torch.arange(s, device=dev).view(s, 1, 1, 1, 1) * (n * n)
    p = torch.arange(n, device=dev).view(1, 1, h, w, 1)
    rows = block + p * n + ys.long() * w + xs.long()
    cols = torch.arange(t, device=dev).view(1, t, 1, 1, 1).expand_as(rows)
    return _sparse(rows[keep], cols[keep], tent[keep], (s * n * n, t))


def _image_seed_matrix(images: torch.Tensor, c_mat: torch.Tensor) -> torch.Tensor:
    """G (C·H·W, S·(H·W)²) of the whole-image layout, stored at the columns C uses."""
    s, ch, h, w = images.shape
    n = h * w
    used = c_mat.indices()[0].unique()  # sorted
    src, rem = used // (n * n), used % (n * n)
    p, q = rem // n, rem % n
    flat = images.reshape(s, ch, n)
    values = flat[src, :, q].T  # (C, U)
    rows = torch.arange(ch, device=images.device)[:, None] * n + p[None]
    cols = used[None].expand(ch, -1)
    keep = values != 0
    return _sparse(rows[keep], cols[keep], values[keep], (ch * n, s * n * n))


def _splat_coefficients(dst_x_for_src: torch.Tensor) -> torch.Tensor:
    """C (H·W·W, T) from the forward map x3 (T, H, W) of each source pixel; NaN: no target."""
    t, h, w = dst_x_for_src.shape
    dev = dst_x_for_src.device
    ok = ~torch.isnan(dst_x_for_src)
    x = torch.where(ok, dst_x_for_src, -2.0).clamp(-2.0, w + 1.0)
    l0 = x.floor()
    cols_l = torch.stack([l0, l0 + 1], dim=-1)  # (T, H, W_src, 2) target columns
    # Eq. 4 literally: y_k = 1 - dist with dist = |x3_k - l|, kept where dist < 1.
    y = 1 - (x[..., None] - cols_l).abs()
    keep = ok[..., None] & (cols_l >= 0) & (cols_l <= w - 1) & (y > 0)
    j = torch.arange(h, device=dev).view(1, h, 1, 1)
    k = torch.arange(w, device=dev).view(1, 1, w, 1)
    rows = (j * w + cols_l.long()) * w + k
    cols = torch.arange(t, device=dev).view(t, 1, 1, 1).expand_as(rows)
    return _sparse(rows[keep], cols[keep], y[keep], (h * w * w, t))
