"""The synthesized views as the sparse product A = G·C of Eqs. 3–6.

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

Two ways to fill C:
    * ``"gather"`` (:meth:`SparseViewOperator.from_maps`): target→source maps, the tent
      weights ``1 − |x − k|`` of the two source neighbours of ``x = src_x[t, j, l]``
      (zeros outside the row), i.e. exactly what kornia's ``remap`` (bilinear,
      ``align_corners=True``, zeros padding) samples in
      :meth:`torch_eigview.warp.NovelViewWarp.apply_maps`.
    * ``"splat"`` (:meth:`SparseViewOperator.from_forward_map`): the literal Eq. 4, a
      forward map x3 of each source pixel k, ``y_k = 1 − |x3_k − l|`` where below 1.
      It is not normalized: where the forward map stretches or folds a row, a target
      pixel's coefficients do not sum to 1.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.errors import check_finite, check_float_tensor, check_ndim
from torch_eigview.warp import WarpMaps

__all__ = ["SparseViewOperator"]

_MODES = ("gather",)


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


def _gather_coefficients(src_x: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """C (S·H·W·W, T) from target→source maps and blend weights, both (S, T, H, W)."""
    s, t, h, w = src_x.shape
    dev = src_x.device
    use = weight != 0
    # Clamping keeps floor() in the int64 range; beyond [-1, W] no neighbour is inside.
    x = torch.where(use, src_x, 0.0).clamp(-2.0, w + 1.0)
    # kornia's remap normalizes pixel columns to [-1, 1] and grid_sample maps them back; in
    # float32 that round trip moves x by ~W·eps. Take the same round trip, so that C holds
    # the weights grid sampling actually applies, not the ones it would in exact arithmetic.
    x = ((2.0 / (w - 1)) * x - 1 + 1) * ((w - 1) / 2) if w > 1 else x
    k0 = x.floor()
    frac = x - k0
    k = torch.stack([k0, k0 + 1], dim=-1)  # (S, T, H, W, 2)
    # Eq. 4 from the target's side: 1 - |x - k| for the two neighbours k of x.
    tent = torch.stack([1 - frac, frac], dim=-1) * weight[..., None]
    keep = use[..., None] & (k >= 0) & (k <= w - 1) & (tent != 0)
    block = torch.arange(s, device=dev).view(s, 1, 1, 1, 1) * (h * w * w)
    jl = torch.arange(h * w, device=dev).view(1, 1, h, w, 1)
    rows = block + jl * w + k.long()
    cols = torch.arange(t, device=dev).view(1, t, 1, 1, 1).expand_as(rows)
    return _sparse(rows[keep], cols[keep], tent[keep], (s * h * w * w, t))


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


@dataclass(frozen=True, eq=False, repr=False)
class SparseViewOperator:
    """Synthesized views as the sparse product A = G·C (Eqs. 3–6).

    Attributes:
        G: (N, M) coalesced sparse COO tensor, N = C·H·W, M = S·H·W·W per object.
        C: (M, T) coalesced sparse COO tensor, one column per synthesized view.
        image_shape: (C, H, W) of a view.
        n_views: T, the number of columns of C (all objects together after :meth:`concat`).

    Example:
        >>> from torch_eigview.correspondence import correspondence_from_disparity
        >>> from torch_eigview.warp import NovelViewWarp
        >>> corr = correspondence_from_disparity(torch.zeros(8, 8))
        >>> maps = NovelViewWarp(alpha=10.0).maps(corr, thetas=[0.0, 5.0, 10.0])
        >>> op = SparseViewOperator.from_maps(torch.rand(2, 1, 8, 8), maps)  # == apply_maps
        >>> op.views().shape
        torch.Size([3, 1, 8, 8])
    """

    G: torch.Tensor
    C: torch.Tensor
    image_shape: tuple[int, int, int]
    n_views: int

    @classmethod
    def from_maps(cls, images: torch.Tensor, maps: WarpMaps, mode: str = "gather") -> SparseViewOperator:
        """Builds G·C for one object from the target→source maps of the warp.

        Args:
            images: (S, C, H, W) seed views of one object, in the order of ``maps``' sources.
            maps: :class:`~torch_eigview.warp.WarpMaps` with ``src_x`` and ``weight`` of
                shape (S, 1, T, H, W) (B = 1). ``src_x`` must be finite where ``weight`` is
                non-zero; entries of zero weight are left out of C whatever their ``src_x``.
                A row warp only: ``src_y`` None or every target pixel's own row.
            mode: ``"gather"``, the bilinear tent weights of kornia's ``remap``; for the
                literal forward (splat) form of Eq. 4 use :meth:`from_forward_map`.

        Returns:
            The operator, with ``views()`` (T, C, H, W) in the dtype of ``images``.

        Raises:
            TypeError: ``images`` is not a float tensor or ``maps`` not a ``WarpMaps``.
            ValueError: bad shapes, B != 1, non-finite values or an unknown ``mode``.
        """
        imgs = check_float_tensor(images, "images")
        check_ndim(imgs, "images", (4,), "(S, C, H, W)")
        check_finite(imgs, "images")
        if not isinstance(mode, str) or mode not in _MODES:
            hint = " (splat needs the forward map: use from_forward_map)" if mode == "splat" else ""
            raise ValueError(f"mode must be one of {_MODES}, got {mode!r}{hint}")
        if not isinstance(maps, WarpMaps):
            raise TypeError(f"maps must be a WarpMaps (NovelViewWarp.maps), got {type(maps).__name__}")
        src_x = check_float_tensor(maps.src_x, "maps.src_x")
        weight = check_float_tensor(maps.weight, "maps.weight")
        check_ndim(src_x, "maps.src_x", (5,), "(S, B, T, H, W)")
        if weight.shape != src_x.shape:
            raise ValueError(
                f"maps.weight must have the shape of maps.src_x {tuple(src_x.shape)}, "
                f"got {tuple(weight.shape)}"
            )
        s, b, t, h, w = src_x.shape
        if b != 1:
            raise ValueError(f"maps must describe one object (B = 1), got B={b}; split the batch per object")
        if (s, h, w) != (imgs.shape[0], imgs.shape[2], imgs.shape[3]):
            raise ValueError(
                f"images must have shape (S, C, H, W) = ({s}, C, {h}, {w}) to match maps.src_x "
                f"{tuple(src_x.shape)}, got {tuple(imgs.shape)}"
            )
        if maps.src_y is not None:
            own_row = torch.arange(h, device=maps.src_y.device).view(1, 1, 1, h, 1)
            if not bool(((maps.src_y == own_row) | (weight == 0)).all()):
                raise ValueError(
                    "maps.src_y must be None or each target pixel's own row (G·C of Eqs. 3–6 warps "
                    "row by row), got rows that move (a tilted camera): use NovelViewWarp.apply_maps"
                )
        check_finite(weight, "maps.weight")
        check_finite(src_x[weight != 0], "maps.src_x (where maps.weight is non-zero)")
        # The maps are cast to the image dtype first, as NovelViewWarp.apply_maps does.
        src_x = src_x[:, 0].to(device=imgs.device, dtype=imgs.dtype)
        weight = weight[:, 0].to(device=imgs.device, dtype=imgs.dtype)
        c_mat = _gather_coefficients(src_x.detach(), weight.detach())
        return cls(_seed_matrix(imgs.detach()), c_mat, (imgs.shape[1], h, w), t)

    @classmethod
    def from_forward_map(cls, image: torch.Tensor, dst_x_for_src: torch.Tensor) -> SparseViewOperator:
        """Builds G·C from one seed view and its forward maps: Eq. 4 as written ("splat").

        Source pixel k of row j lands at ``x3 = dst_x_for_src[t, j, k]`` (Eq. 2,
        ``a·x1 + b·x2``) and gives target pixel (j, l) the coefficient
        ``y_k = 1 − |x3 − l|`` where that is positive, i.e. to ``floor(x3)`` and
        ``floor(x3) + 1`` inside [0, W − 1]. Coefficients are not normalized.

        Args:
            image: (C, H, W) the seed view.
            dst_x_for_src: (T, H, W) forward map of each source pixel, in pixels; NaN
                marks a source pixel that contributes to no target (e.g. no correspondence).

        Returns:
            The operator, with ``views()`` (T, C, H, W) in the dtype of ``image``.

        Raises:
            TypeError: an argument is not a float tensor.
            ValueError: bad shapes or infinite map values.
        """
        img = check_float_tensor(image, "image")
        check_ndim(img, "image", (3,), "(C, H, W)")
        check_finite(img, "image")
        dst = check_float_tensor(dst_x_for_src, "dst_x_for_src")
        check_ndim(dst, "dst_x_for_src", (3,), "(T, H, W)")
        if dst.shape[1:] != img.shape[1:]:
            raise ValueError(
                f"dst_x_for_src must have shape (T, H, W) = (T, {img.shape[1]}, {img.shape[2]}) "
                f"to match image {tuple(img.shape)}, got {tuple(dst.shape)}"
            )
        check_finite(dst[~torch.isnan(dst)], "dst_x_for_src (NaN allowed: no target)")
        dst = dst.detach().to(device=img.device, dtype=img.dtype)
        _, h, w = img.shape
        return cls(
            _seed_matrix(img.detach()[None]), _splat_coefficients(dst), (img.shape[0], h, w), dst.shape[0]
        )

    @classmethod
    def concat(cls, ops: Sequence[SparseViewOperator]) -> SparseViewOperator:
        """Several objects (Sec. 4.2): G = [G_1 … G_m], C = blockdiag(C_1 … C_m).

        Then G·C = [A_1 … A_m]: the views of all objects, object by object.

        Raises:
            TypeError: ``ops`` is not a sequence of operators, or dtypes differ.
            ValueError: ``ops`` is empty, or image shapes or devices differ.
        """
        if isinstance(ops, SparseViewOperator) or not isinstance(ops, Sequence):
            raise TypeError(f"ops must be a sequence of SparseViewOperator, got {type(ops).__name__}")
        if not ops:
            raise ValueError("ops must be a non-empty sequence of SparseViewOperator, got an empty one")
        for i, op in enumerate(ops):
            if not isinstance(op, SparseViewOperator):
                raise TypeError(f"ops[{i}] must be a SparseViewOperator, got {type(op).__name__}")
            if op.image_shape != ops[0].image_shape:
                raise ValueError(
                    f"ops[{i}].image_shape={op.image_shape} must equal "
                    f"ops[0].image_shape={ops[0].image_shape}"
                )
            if op.G.dtype != ops[0].G.dtype:
                raise TypeError(f"ops[{i}] has dtype {op.G.dtype}, ops[0] has {ops[0].G.dtype}")
            if op.G.device != ops[0].G.device:
                raise ValueError(f"ops[{i}] is on {op.G.device}, ops[0] on {ops[0].G.device}")
        g_idx, g_val, c_idx, c_val = [], [], [], []
        m_off = t_off = 0
        for op in ops:
            gi, ci = op.G.indices(), op.C.indices()
            g_idx.append(torch.stack([gi[0], gi[1] + m_off]))
            c_idx.append(torch.stack([ci[0] + m_off, ci[1] + t_off]))
            g_val.append(op.G.values())
            c_val.append(op.C.values())
            m_off += op.G.shape[1]
            t_off += op.n_views
        n = ops[0].G.shape[0]
        g = torch.sparse_coo_tensor(torch.cat(g_idx, 1), torch.cat(g_val), (n, m_off), check_invariants=False)
        g = g.coalesce()
        # Row and column offsets grow with the block, so blockdiag(C_i) is already sorted.
        c = torch.sparse_coo_tensor(
            torch.cat(c_idx, 1), torch.cat(c_val), (m_off, t_off), is_coalesced=True, check_invariants=False
        )
        return cls(g, c, ops[0].image_shape, t_off)

    @property
    def nnz(self) -> tuple[int, int]:
        """Stored non-zeros ``(nnz(G), nnz(C))``."""
        return int(self.G._nnz()), int(self.C._nnz())

    def data_matrix(self) -> torch.Tensor:
        """The dense (N, T) data matrix A = G·C (Eq. 6), views as columns."""
        # sparse·sparse: C densified would be (S·H·W·W, T), 86M values at 128² and T = 41.
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "Sparse CSR tensor support is in beta")
            return torch.sparse.mm(self.G, self.C).to_dense()

    def views(self) -> torch.Tensor:
        """The synthesized views, dense (T, C, H, W): the columns of A reshaped."""
        return self.data_matrix().T.reshape(self.n_views, *self.image_shape)

    def __repr__(self) -> str:
        nnz_g, nnz_c = self.nnz
        return (
            f"SparseViewOperator(image_shape={self.image_shape}, n_views={self.n_views}, "
            f"G={tuple(self.G.shape)} nnz={nnz_g}, C={tuple(self.C.shape)} nnz={nnz_c}, dtype={self.G.dtype})"
        )
