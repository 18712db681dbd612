"""The synthesized views as the sparse product A = G·C of Eqs. 3–6.

Convention:
    Images are (C, H, W); x is the column, y the row; pixel centres at integers. A view
    is flattened row-major over (C, H, W) into a column of A; G holds the seed views'
    rows (or whole images) in one column block per target pixel and C the interpolation
    coefficients of each target pixel (Eq. 3's ``C_j^l``), the blend weights folded in:
    the exact index layout is in :mod:`torch_eigview.warp.coefficients`.

Two ways to fill C:
    * ``"gather"`` (:meth:`SparseViewOperator.from_maps`): target→source maps, the tent
      weights ``1 − |x − k|`` of the two source neighbours of ``x = src_x[t, j, l]``
      (zeros outside the row), i.e. exactly what
      :meth:`torch_eigview.warp.novel_view.NovelViewWarp.apply_maps` samples (kornia's
      ``remap``'s samples: bilinear, ``align_corners=True``, zeros padding).
    * ``"splat"`` (:meth:`SparseViewOperator.from_forward_map`): the literal Eq. 4, a
      forward map x3 of each source pixel k, ``y_k = 1 − |x3_k − l|`` where below 1.
      It is not normalized: where the forward map stretches or folds a row, a target
      pixel's coefficients do not sum to 1.

2D warps (Sec. 4, perspective cameras; ``layout="image"``):
    When rows move, a target pixel's coefficient vector spans the whole image: G is
    (C·H·W, S·(H·W)²) with row ``(c, p)`` holding all of ``I_s[c]`` in column block
    ``(s, p)``, ``G[(c, p), (s, p, q)] = I_s[c, q]`` (column ``s·(H·W)² + p·H·W + q``),
    and column t of C holds at rows ``(s, p, q)`` the 2D bilinear weights of grid
    sampling (four per target pixel). Stored in full, G would hold C·S·(H·W)² values
    (2.7e8 at 128²), so only its columns that C uses are stored: every other column of
    G meets a zero row of C, and G·C is the same product.

More than two seed views (Sec. 4.1): :meth:`SparseViewOperator.concat` of the seed
pairs' operators is the direct form A = [G1C1 … G(m−1)C(m−1)];
:meth:`SparseViewOperator.common_factor` the paper's G1·[C1, C̃2, …] with
C̃n = G1⁺·Gn·Cn, equal to it exactly when G1 has full row rank.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.check import check_finite, check_float_tensor, check_ndim
from torch_eigview.warp.coefficients import (
    _gather_coefficients,
    _gather_coefficients_2d,
    _image_seed_matrix,
    _seed_matrix,
    _splat_coefficients,
)
from torch_eigview.warp.maps import WarpMaps

__all__ = ["SparseViewOperator"]

_MODES = ("gather",)
LAYOUTS = ("row", "image")


def _gram_blocks(op: SparseViewOperator) -> torch.Tensor:
    """(H·W, C, C) blocks of G·Gᵀ, one per target pixel (G's rows of different pixels
    share no column, in either layout)."""
    ch, h, w = op.image_shape
    n = h * w
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Sparse CSR tensor support is in beta")
        gram = torch.sparse.mm(op.G, op.G.t().coalesce()).coalesce()
    (r1, r2), v = gram.indices(), gram.values()
    blocks = torch.zeros(n, ch, ch, dtype=op.G.dtype, device=op.G.device)
    blocks.index_put_((r1 % n, r1 // n, r2 // n), v, accumulate=True)
    return blocks


def _checked_maps(maps: object, imgs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, bool]:
    """``(src_x, weight, rows_move)`` of :meth:`SparseViewOperator.from_maps`'s ``maps``,
    validated against the seed images (S, C, H, W); ``rows_move``: ``src_y`` leaves a
    target pixel's own row somewhere it has weight."""
    if not isinstance(maps, WarpMaps):
        raise TypeError(f"maps must be a WarpMaps (NovelViewWarp.maps), got {type(maps).__name__}")
    src_x = check_float_tensor(maps.src_x, "maps.src_x")
    weight = check_float_tensor(maps.weight, "maps.weight")
    check_ndim(src_x, "maps.src_x", (5,), "(S, B, T, H, W)")
    if weight.shape != src_x.shape:
        raise ValueError(
            f"maps.weight must have the shape of maps.src_x {tuple(src_x.shape)}, got {tuple(weight.shape)}"
        )
    s, b, _, h, w = src_x.shape
    if b != 1:
        raise ValueError(f"maps must describe one object (B = 1), got B={b}; split the batch per object")
    if maps.row0 != 0:
        raise ValueError(
            f"maps must cover every row of the images ({imgs.shape[2]}), got rows {maps.row0}..{maps.row0 + h - 1} "
            "(maps built with support= hold a band of rows): build them without support"
        )
    if (h, w) != tuple(imgs.shape[2:]):
        # Name the sizes first: maps of other images are the likelier cause; a band of rows
        # (support=) is possible only where the widths agree and the maps hold fewer rows.
        band = (
            "; or the maps hold a band of rows (built with support=): build them without support"
            if w == imgs.shape[3] and h < imgs.shape[2]
            else ""
        )
        raise ValueError(
            f"images are (H, W)=({imgs.shape[2]}, {imgs.shape[3]}), the maps were built for (H, W)=({h}, {w}) "
            f"(maps.src_x {tuple(src_x.shape)}): build the maps for these images{band}"
        )
    if s != imgs.shape[0]:
        raise ValueError(
            f"images must have shape (S, C, H, W) = ({s}, C, {h}, {w}) to match maps.src_x "
            f"{tuple(src_x.shape)}, got {tuple(imgs.shape)}"
        )
    if maps.src_y is None:
        return src_x, weight, False
    src_y = check_float_tensor(maps.src_y, "maps.src_y")
    if src_y.shape != src_x.shape:
        raise ValueError(
            f"maps.src_y must have the shape of maps.src_x {tuple(src_x.shape)}, got {tuple(src_y.shape)}"
        )
    own_row = torch.arange(h, device=src_y.device).view(1, 1, 1, h, 1)
    return src_x, weight, not bool(((src_y == own_row) | (weight == 0)).all())


def _use_image_layout(layout: str, rows_move: bool) -> bool:
    """Whether :meth:`SparseViewOperator.from_maps` builds the whole-image layout."""
    if layout not in LAYOUTS and layout != "auto":
        raise ValueError(f"layout must be 'auto' or one of {LAYOUTS}, got {layout!r}")
    if layout == "row" and rows_move:
        raise ValueError(
            "layout='row' needs maps.src_y None or each target pixel's own row (Eqs. 3–6 warp "
            "row by row), got rows that move: use layout='image' (Sec. 4's whole-image vectors)"
        )
    return layout == "image" or (layout == "auto" and rows_move)


def _checked_masks(masks: object, shape: tuple[int, int, int]) -> torch.Tensor:
    """Seed masks of shape (S, H, W), detached."""
    if not isinstance(masks, torch.Tensor):
        raise TypeError(f"masks must be a tensor, got {type(masks).__name__}")
    if masks.shape != shape:
        raise ValueError(f"masks must have shape (S, H, W) = {shape}, got {tuple(masks.shape)}")
    return masks.detach()


@dataclass(frozen=True, eq=False, repr=False)
class SparseViewOperator:
    """Synthesized views as the sparse product A = G·C (Eqs. 3–6).

    Attributes:
        G: (N, M) coalesced sparse COO tensor, N = C·H·W, M = S·H·W·W per object.
        C: (M, T) coalesced sparse COO tensor, one column per synthesized view.
        image_shape: (C, H, W) of a view.
        n_views: T, the number of columns of C (all objects together after :meth:`concat`).
        layout: ``"row"`` (M = S·H·W·W) or ``"image"`` (M = S·(H·W)², Sec. 4's 2D warps).

    Example:
        >>> from torch_eigview.geometry.correspondence import correspondence_from_disparity
        >>> from torch_eigview.warp.novel_view import NovelViewWarp
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
    layout: str = "row"

    @classmethod
    def from_maps(
        cls,
        images: torch.Tensor,
        maps: WarpMaps,
        mode: str = "gather",
        layout: str = "auto",
        masks: torch.Tensor | None = None,
    ) -> SparseViewOperator:
        """Builds G·C for one object from the target→source maps of the warp.

        Args:
            images: (S, C, H, W) seed views of one object, in the order of ``maps``' sources.
            maps: :class:`~torch_eigview.warp.novel_view.WarpMaps` with ``src_x`` and ``weight`` of
                shape (S, 1, T, H, W) (B = 1). ``src_x`` must be finite where ``weight`` is
                non-zero; entries of zero weight are left out of C whatever their ``src_x``.
                ``src_y`` (same shape) when rows move.
            mode: ``"gather"``, the bilinear tent weights of kornia's ``remap``; for the
                literal forward (splat) form of Eq. 4 use :meth:`from_forward_map`.
            layout: ``"row"`` (Eqs. 3–6: a coefficient vector per row, rows must not
                move), ``"image"`` (Sec. 4: whole-image coefficient vectors, any 2D
                warp) or ``"auto"``: ``"row"`` unless ``maps.src_y`` moves rows.
            masks: optional (S, H, W) foreground masks of the seed views: the
                silhouette-aware weights of ``NovelViewWarp.apply_maps(..., masks)``
                (foreground taps only, renormalized per target pixel; background where
                the foreground share is below 1/2).

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
        src_x, weight, rows_move = _checked_maps(maps, imgs)
        use_image = _use_image_layout(layout, rows_move)
        s, _, t, h, w = src_x.shape
        if masks is not None:
            masks = _checked_masks(masks, (s, h, w)).to(imgs.device)
        check_finite(weight, "maps.weight")
        check_finite(src_x[weight != 0], "maps.src_x (where maps.weight is non-zero)")
        # The maps are cast to the image dtype first, as NovelViewWarp.apply_maps does.
        src_x = src_x[:, 0].to(device=imgs.device, dtype=imgs.dtype).detach()
        weight = weight[:, 0].to(device=imgs.device, dtype=imgs.dtype).detach()
        shape = (imgs.shape[1], h, w)
        if not use_image:
            return cls(_seed_matrix(imgs.detach()), _gather_coefficients(src_x, weight, masks), shape, t)
        if maps.src_y is None:
            src_y = torch.arange(h, dtype=imgs.dtype, device=imgs.device).view(1, 1, h, 1).expand_as(src_x)
        else:
            check_finite(maps.src_y[maps.weight != 0], "maps.src_y (where maps.weight is non-zero)")
            src_y = maps.src_y[:, 0].to(device=imgs.device, dtype=imgs.dtype).detach()
        c_mat = _gather_coefficients_2d(src_x, src_y, weight, masks)
        return cls(_image_seed_matrix(imgs.detach(), c_mat), c_mat, shape, t, "image")

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
            if op.layout != ops[0].layout:
                raise ValueError(f"ops[{i}].layout={op.layout!r} must equal ops[0].layout={ops[0].layout!r}")
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
        return cls(g, c, ops[0].image_shape, t_off, ops[0].layout)

    @classmethod
    def common_factor(cls, ops: Sequence[SparseViewOperator]) -> SparseViewOperator:
        """Sec. 4.1's common-factor form of one object's seed pairs: G1·[C1, C̃2, …].

        ``ops[n]`` is the operator of the (n + 1)-th consecutive seed pair; the direct form
        is ``concat(ops)`` = [G1C1 … Gm−1Cm−1]. Here G1 is brought out as the common
        factor: ``C̃n = G1⁺·Gn·Cn`` with the pseudo-inverse ``G1⁺ = G1ᵀ(G1G1ᵀ)⁺``, so that
        ``G1·C̃n = P·Gn·Cn`` with P the projector onto the range of G1G1ᵀ. Hence the
        two forms are equal when G1 has full row rank (:meth:`full_row_rank`): in the row
        layout, when every image row (all channels together) of the first pair's seed
        views is non-zero; in the image layout (G stored at the columns C uses), when
        every target pixel of the first pair samples some non-zero seed pixel. A
        seed pair whose views share an all-black row (COIL's background) loses rank, and
        then the common form keeps only what the other pairs put in rows that G1 spans:
        a zero row of G1 forces a zero row of G1·C̃n.

        G1G1ᵀ is block diagonal (a C×C block per target pixel), so G1⁺ costs little,
        but C̃n is dense wherever the first pair's seeds are non-zero: it stores about
        S·W (row layout) or S·H·W (image layout) values per pixel and view, against
        the direct form's few. It is the paper's algebra, for small images and for
        checking; the direct form is the default everywhere else.

        Raises:
            TypeError, ValueError: as :meth:`concat`.
        """
        direct = cls.concat(ops)  # validates ops
        first = ops[0]
        blocks = _gram_blocks(first)
        pinv = torch.linalg.pinv(blocks)  # (H·W, C, C)
        ch, h, w = first.image_shape
        n = h * w
        parts = [first.C]
        for op in ops[1:]:
            a_n = op.data_matrix()  # (C·H·W, T_n)
            z = torch.einsum("pcd,dpt->cpt", pinv, a_n.view(ch, n, -1)).reshape(ch * n, -1)
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", "Sparse CSR tensor support is in beta")
                parts.append(torch.sparse.mm(first.G.t().coalesce(), z).to_sparse())
        c = torch.cat([p.coalesce() for p in parts], dim=1).coalesce()
        return cls(first.G, c, first.image_shape, direct.n_views, first.layout)

    def full_row_rank(self) -> bool:
        """Whether G has full row rank (every C×C block of G·Gᵀ is non-singular)."""
        blocks = _gram_blocks(self)
        return bool((torch.linalg.matrix_rank(blocks) == blocks.shape[-1]).all())

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
            f"G={tuple(self.G.shape)} nnz={nnz_g}, C={tuple(self.C.shape)} nnz={nnz_c}, "
            f"layout={self.layout!r}, dtype={self.G.dtype})"
        )
