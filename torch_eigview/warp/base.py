"""What the view-warp modules share: seed views sampled with target→source maps and blended.

Convention:
    Images are (C, H, W) (batched (B, C, H, W)); x is the column, y the row; pixel
    centres are at integer coordinates. A subclass builds :class:`~torch_eigview.warp.maps.WarpMaps`
    (target → source, in pixels) from the correspondences of the two seed views; the seed
    images are then sampled and blended with the maps' weights. The sampling is
    ``torch.nn.functional.grid_sample`` called directly (bilinear, zero padding,
    ``align_corners=True``: the tent weights of Eq. 4), one call per source for all
    angles, on coordinates normalized by kornia's rule (:func:`kornia_scale`): the samples
    of :func:`kornia.geometry.transform.remap` with ``align_corners=True`` bit for bit,
    which stays the reference the tests compare with (``tests/warp/test_fast_paths.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
import torch.nn.functional as F

from torch_eigview.check import as_angle_tensor, check_alpha, check_float_tensor, check_ndim, check_number
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.warp.maps import WarpMaps, _renormalize

__all__ = ["BLENDS", "ViewWarp", "kornia_scale"]

#: How two seed views that both see a target pixel share it (a view warp's ``blend``).
BLENDS = ("linear", "nearest")


class ViewWarp(torch.nn.Module):
    """Synthesizes novel views from one or two seed views at angles 0 and ``alpha``.

    A subclass implements :meth:`maps` for its camera model; sampling, blending and
    :meth:`forward` are the same for every camera.

    Args:
        alpha: angle of the second seed view in degrees.
        max_stretch: a forward-mapped segment or triangle edge longer than this (pixels)
            is a depth jump, not a surface: it is left to the other view.
        blend: how two seed views that both see a target pixel share it: ``"linear"``
            (weights 1 − θ/α and θ/α, a cross-dissolve) or ``"nearest"`` (the seed nearer
            in angle alone, seed 1 up to α/2).
    """

    def __init__(self, alpha: float, *, max_stretch: float = 3.0, blend: str = "linear") -> None:
        super().__init__()
        self.alpha = check_alpha(alpha)
        if blend not in BLENDS:
            raise ValueError(f"blend must be one of {BLENDS}, got {blend!r}")
        self.blend = blend
        self.max_stretch = check_number(max_stretch, "max_stretch")
        if not self.max_stretch > 0:
            raise ValueError(f"max_stretch={max_stretch} must be positive")

    def maps(self, correspondence: Correspondence, thetas: object, n_sources: int = 2) -> WarpMaps:
        """Target→source maps and blend weights for the novel angles ``thetas``.

        Args:
            correspondence: (B, H, W) correspondences between the seed views.
            thetas: (T,) novel angles in degrees from the first seed view, in (−90, 90).
            n_sources: 2 to blend both seed views, 1 to warp view 1 alone.

        Returns:
            :class:`~torch_eigview.warp.maps.WarpMaps` with S = ``n_sources``.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement maps()")

    @staticmethod
    def _check_n_sources(n_sources: int) -> None:
        if n_sources not in (1, 2):
            raise ValueError(f"n_sources must be 1 or 2, got {n_sources}")

    @staticmethod
    def _novel_angles(thetas: object, batch: int | None = None) -> torch.Tensor:
        """(T,) float64 degrees, each within a quarter turn of the first seed view.

        With ``batch`` (the number of objects B), a 2-D tensor is taken as (B, T): T angles
        of each object's own (returned as (B, T); B may be 0).
        """
        if batch is not None and isinstance(thetas, torch.Tensor) and thetas.ndim == 2:
            if thetas.shape[0] != batch or thetas.shape[1] == 0:
                raise ValueError(
                    f"thetas of shape (B, T) must have B = {batch} rows (one per object) and T >= 1, "
                    f"got shape {tuple(thetas.shape)}"
                )
            flat = thetas.reshape(-1)
            theta = (as_angle_tensor(flat, "thetas") if flat.numel() else flat.detach().double()).view(
                thetas.shape
            )
        else:
            theta = as_angle_tensor(thetas, "thetas")
        if bool((theta.abs() >= 90).any()):
            bad = theta[theta.abs() >= 90].tolist()
            shown = ", ".join(f"{t:g}" for t in bad[:5]) + (
                f", ... ({len(bad)} in all)" if len(bad) > 5 else ""
            )
            raise ValueError(
                f"thetas must lie within (-90, 90) degrees of the first seed view, got {shown}: "
                "beyond that the seed views show the object's other side"
            )
        return theta

    def _share_of_second(self, theta_rad: torch.Tensor) -> torch.Tensor:
        """The second seed's weight where both seeds see a pixel (``blend``), per angle."""
        lam2 = (theta_rad / math.radians(self.alpha)).clamp(0, 1)
        return lam2 if self.blend == "linear" else (lam2 > 0.5).to(lam2.dtype)

    @staticmethod
    def apply_maps(
        maps: WarpMaps, views: torch.Tensor | Sequence[torch.Tensor], masks: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Samples and blends the seed views with precomputed maps.

        Args:
            maps: :class:`~torch_eigview.warp.maps.WarpMaps` with S sources for B objects and T angles.
            views: (S, B, C, H, W) seed images, or a sequence of the S (B, C, H, W) ones
                (not stacked: one copy of the seeds fewer).
            masks: optional (S, B, H, W) foreground masks of the seed views (non-zero is
                foreground, any dtype):
                *silhouette-aware* sampling. Each target pixel's bilinear taps, over both
                seeds and with the blend weights, then count foreground source pixels
                only and are renormalized to sum to 1; a target pixel whose foreground
                share is below 1/2 is background (0). Without it a pixel on the
                silhouette mixes object and background (a dark rim); with it the result
                is still linear in ``views`` for fixed masks (the weights of
                :meth:`SparseViewOperator.from_maps` with ``masks``; the two round the
                foreground share differently, so a pixel within float rounding of 1/2
                can fall on different sides of it).

        Maps that hold a band of rows (``maps.row0``, built with ``support``) fill that band;
        the other rows of the result are 0, constants (no gradient flows from them to the
        seeds' zero pixels, as it would through whole-grid maps).

        Returns:
            (B, T, C, H, W) synthesized views.
        """
        s, b, _, rows, w = maps.src_x.shape
        sources = list(views.unbind(0)) if isinstance(views, torch.Tensor) else list(views)
        if len(sources) != s:
            raise ValueError(f"views must hold the maps' S = {s} seed views, got {len(sources)}")
        c, dtype, h = sources[0].shape[1], sources[0].dtype, sources[0].shape[-2]
        if not 0 <= maps.row0 <= h - rows:
            raise ValueError(
                f"maps hold rows {maps.row0}..{maps.row0 + rows - 1}, which do not lie in the views' {h} rows"
            )
        if masks is not None:
            if masks.shape != (s, b, h, w):
                raise ValueError(
                    f"masks must have shape (S, B, H, W) = {(s, b, h, w)}, got {tuple(masks.shape)}"
                )
            m = (masks.to(sources[0].device) != 0).to(dtype)[:, :, None]
            # The mask rides along: one warp for both.
            sources = [torch.cat([v * m[i], m[i]], dim=1) for i, v in enumerate(sources)]
        warped = _sample_views(sources, maps.src_x, maps.src_y, maps.row0)  # S of (B, T, C', R, W)
        # Weighted in place: the samples are this call's own temporaries.
        out = warped[0].mul_(maps.weight[0].to(dtype)[:, :, None])
        for i in range(1, s):
            out.add_(warped[i].mul_(maps.weight[i].to(dtype)[:, :, None]))
        out = out.contiguous() if masks is None else _renormalize(out[:, :, :c], out[:, :, c:])
        if rows == h:
            return out
        whole = out.new_zeros((*out.shape[:3], h, w))
        whole[..., maps.row0 : maps.row0 + rows, :] = out
        return whole

    def forward(
        self,
        view1: torch.Tensor,
        view2: torch.Tensor | None = None,
        *,
        correspondence: Correspondence,
        thetas: object,
        masks: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Synthesizes the novel views.

        Args:
            view1: (B, C, H, W) or (C, H, W) first seed view (angle 0).
            view2: same shape, second seed view (angle ``alpha``), or None to warp view 1 alone.
            correspondence: (B, H, W) correspondences between the seed views.
            thetas: (T,) novel angles in degrees, the same for every object; or, where the
                subclass's :meth:`maps` accepts it (:class:`NovelViewWarp`), a (B, T) tensor:
                each object's own T angles, all B warped in one batched pass.
            masks: optional foreground masks of the seed views, (S, B, H, W) (or (S, H, W)
                unbatched; S = 1 or 2 as views are given): silhouette-aware sampling, see
                :meth:`apply_maps`.

        Returns:
            (B, T, C, H, W) views (or (T, C, H, W) for unbatched input); differentiable
            with respect to ``view1`` and ``view2``.
        """
        v1 = check_float_tensor(view1, "view1")
        check_ndim(v1, "view1", (3, 4), "(B, C, H, W) or (C, H, W)")
        unbatched = v1.ndim == 3
        views = [v1[None] if unbatched else v1]
        if view2 is not None:
            v2 = check_float_tensor(view2, "view2")
            if v2.shape != v1.shape:
                raise ValueError(
                    f"view2 must have the shape of view1 {tuple(v1.shape)}, got {tuple(v2.shape)}"
                )
            if v2.dtype != v1.dtype:
                raise TypeError(f"view2 must have the dtype of view1 ({v1.dtype}), got {v2.dtype}")
            views.append(v2[None] if unbatched else v2)
        b, _, h, w = views[0].shape
        if correspondence.shape != (b, h, w):
            raise ValueError(
                f"correspondence must have shape (B, H, W) = {(b, h, w)} to match the views, "
                f"got {correspondence.shape}"
            )
        if masks is not None:
            if not isinstance(masks, torch.Tensor):
                raise TypeError(f"masks must be a tensor, got {type(masks).__name__}")
            expected = (len(views), h, w) if unbatched else (len(views), b, h, w)
            if masks.shape != expected:
                raise ValueError(f"masks must have shape {expected} (S, [B,] H, W), got {tuple(masks.shape)}")
            masks = (masks[:, None] if unbatched else masks).to(v1.device)
        corr = correspondence.to(device=v1.device)
        maps = self.maps(corr, thetas, n_sources=len(views))
        out = self.apply_maps(maps, views, masks)
        return out[0] if unbatched else out


def kornia_scale(n: int, like: torch.Tensor) -> tuple[torch.Tensor, float]:
    """kornia's :func:`~kornia.geometry.conversions.normalize_pixel_coordinates` along an
    axis of ``n`` pixels, as a factor and an offset: the grid coordinate of pixel x is
    ``x * factor - offset``, the factor ``2 / (n - 1)`` in ``like``'s dtype, the offset 1;
    1 and 0 for a single pixel.

    A copy of kornia's rule rather than a call, for the view sampler, which normalizes
    every pixel's coordinates: kornia's function takes and returns interleaved (…, 2)
    (x, y) pairs, so calling it costs a stack of both coordinates into a (…, 2) tensor, a
    pass that broadcasts the factor over the pairs, and a second full-size grid for its
    result, where this factor lets the sampler write each coordinate's plane in one pass
    into the only full-size buffer. (The separable sampler of
    :func:`~torch_eigview.warp.normalize.normalize_extent` has W + H coordinates to
    normalize, not every pixel's, and calls kornia's function.) For
    float32 and float64 the factor is kornia's bit for bit (kornia rounds the double
    ``2 / (n - 1)`` to the coordinates' dtype, this divides in that dtype: the same
    correctly rounded quotient), which ``tests/warp/test_fast_paths.py`` checks against
    kornia's function itself."""
    one = torch.ones((), dtype=like.dtype, device=like.device)
    return (one, 0.0) if n == 1 else (2.0 / (one * n - 1.0), 1.0)


def _sample_views(
    views: list[torch.Tensor], src_x: torch.Tensor, src_y: torch.Tensor | None, row0: int = 0
) -> list[torch.Tensor]:
    """Bilinear samples of the seed views at the maps, all angles of a source in one call.

    What kornia's ``remap`` computes, through ``grid_sample`` directly: ``remap`` takes
    one (B, H, W) map per image, so it would need T copies of each seed (one per angle)
    and a call per copy; here the T angles' points go into one grid per (source,
    object), (B, T·H, W), and a seed image is read in place. The coordinates are
    normalized with kornia's rule (:func:`kornia_scale`) and sampled with zero padding and
    ``align_corners=True``, so the samples equal ``remap``'s bit for bit.

    Args:
        views: the S seed images, (B, C, H, W) each.
        src_x: (S, B, T, R, W) source columns of target rows ``row0 … row0 + R − 1`` (R = H:
            all); ``src_y`` the same rows, or None (own row).

    Returns:
        S samples, (B, T, C, R, W) each.
    """
    b, _, h, w = views[0].shape
    t, rows = src_x.shape[2], src_x.shape[3]
    dtype, device = views[0].dtype, views[0].device
    (fx, ox), (fy, oy) = kornia_scale(w, views[0]), kornia_scale(h, views[0])
    ys = (
        torch.arange(row0, row0 + rows, dtype=dtype, device=device).view(rows, 1)
        if src_y is None
        else src_y.to(dtype)
    )
    xs = src_x.to(dtype)
    if dtype in (torch.float32, torch.float64) and not (
        torch.is_grad_enabled() and (xs.requires_grad or ys.requires_grad)
    ):
        # One plane per coordinate, each written in one contiguous pass, and read through a
        # permuted view as (…, 2) pairs (grid_sample reads a grid through its strides, so
        # the view serves as an interleaved grid would, which costs a strided pass or a
        # stack to write). The planes are the only full-size buffer, which keeps a call's
        # peak of memory low.
        planes = xs.new_empty((2, *xs.shape))
        torch.mul(xs, fx, out=planes[0]).sub_(ox)
        torch.mul(ys.expand_as(xs), fy, out=planes[1]).sub_(oy)
        grid = planes.movedim(0, -1)
    else:
        grid = torch.stack([xs * fx - ox, (ys * fy - oy).expand_as(xs)], dim=-1)
    return [
        F.grid_sample(
            v, grid[i].view(b, t * rows, w, 2), mode="bilinear", padding_mode="zeros", align_corners=True
        )
        .view(b, v.shape[1], t, rows, w)
        .transpose(1, 2)
        for i, v in enumerate(views)
    ]
