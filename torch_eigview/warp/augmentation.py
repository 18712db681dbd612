"""A random turntable rotation as a data augmentation, in the style of ``kornia.augmentation``.

Convention:
    Images are (B, C, H, W); x is the column, y the row; pixel centres at integer
    coordinates. Each sample is a pair of seed views of one object (angles 0 and
    ``alpha``) with their (B, H, W) correspondences; the augmented sample is the object
    turned by θ about the vertical axis (Eq. 2), synthesized by
    :class:`~torch_eigview.warp.novel_view.NovelViewWarp` with target → source maps.

As in kornia, :meth:`RandomTurntableRotation.forward_parameters` draws the parameters
(one θ and one apply flag per sample), ``forward(..., params=...)`` replays given ones and
``_params`` keeps those of the last call. The B objects, each at its own θ, are warped in
one batched pass (per-object angles of :meth:`NovelViewWarp.maps`), not B calls.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import torch
from torch import nn

from torch_eigview.check import check_float_tensor, check_ndim, check_number
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.warp.novel_view import NovelViewWarp

__all__ = ["RandomTurntableRotation"]

_PARAM_KEYS = ("degrees", "batch_prob")


def _degree_range(degrees: object) -> tuple[float, float]:
    """``degrees`` (a number d for (−d, d), or a pair (lo, hi)) as a range inside (−90, 90)."""
    if isinstance(degrees, Sequence) and not isinstance(degrees, str):
        if len(degrees) != 2:
            raise ValueError(f"degrees must be a number or a pair (lo, hi), got {degrees!r}")
        lo, hi = (check_number(v, "degrees") for v in degrees)
    else:
        d = check_number(degrees, "degrees")
        if not (math.isfinite(d) and d >= 0):
            raise ValueError(
                f"degrees={degrees!r} must be a finite number >= 0 as a single number (the range is (-d, d))"
            )
        lo, hi = -d, d
    if not (math.isfinite(lo) and math.isfinite(hi) and -90 < lo <= hi < 90):
        raise ValueError(
            f"degrees must be a range (lo, hi) with -90 < lo <= hi < 90 (a quarter turn at most, "
            f"beyond which the seed views show the other side), got {degrees!r}"
        )
    return lo, hi


class RandomTurntableRotation(nn.Module):
    """Turns each object of a batch by its own random angle about the turntable's axis.

    For each sample an angle θ is drawn uniformly from ``degrees`` and, with probability
    ``p``, the sample becomes its novel view at θ (Eq. 2 from its two seed views and their
    correspondences); otherwise it is its first seed view unchanged. The result is a
    differentiable function of the seed views. Like kornia's augmentations it applies in
    training and evaluation mode alike.

    Args:
        degrees: the range of θ in degrees from the first seed view: a number d for
            (−d, d), or a pair (lo, hi) with −90 < lo <= hi < 90.
        alpha: angle of the second seed view in degrees.
        p: probability that a sample is turned.
        same_on_batch: one draw (θ and whether to apply it) for the whole batch.
        generator: the random source of the draws; None draws from torch's global
            generator (reproducible under :func:`torch.manual_seed`).
        **warp_options: keyword options of :class:`~torch_eigview.warp.novel_view.NovelViewWarp`
            (``center``, ``max_stretch``, ``depth_sign``, ``elevation``, ``camera``, ``blend``).

    Example:
        >>> from torch_eigview.geometry import correspondence_from_disparity
        >>> _ = torch.manual_seed(0)
        >>> aug = RandomTurntableRotation((-20.0, 20.0), alpha=10.0, p=1.0)
        >>> view1, view2 = torch.rand(4, 1, 8, 8), torch.rand(4, 1, 8, 8)
        >>> corr = correspondence_from_disparity(torch.zeros(4, 8, 8))
        >>> out = aug(view1, view2, correspondence=corr)
        >>> out.shape, aug._params["degrees"].shape
        (torch.Size([4, 1, 8, 8]), torch.Size([4]))
        >>> torch.equal(aug(view1, view2, correspondence=corr, params=aug._params), out)
        True
    """

    def __init__(
        self,
        degrees: float | tuple[float, float],
        alpha: float,
        *,
        p: float = 0.5,
        same_on_batch: bool = False,
        generator: torch.Generator | None = None,
        **warp_options: object,
    ) -> None:
        super().__init__()
        self.degrees = _degree_range(degrees)
        self.p = check_number(p, "p")
        if not 0 <= self.p <= 1:
            raise ValueError(f"p={p} must be a probability in [0, 1]")
        if not isinstance(same_on_batch, bool):
            raise TypeError(f"same_on_batch must be a bool, got {type(same_on_batch).__name__}")
        self.same_on_batch = same_on_batch
        if generator is not None and not isinstance(generator, torch.Generator):
            raise TypeError(f"generator must be a torch.Generator or None, got {type(generator).__name__}")
        self.generator = generator
        self.warp = NovelViewWarp(alpha, **warp_options)  # type: ignore[arg-type]
        self._params: dict[str, torch.Tensor] = {}

    def extra_repr(self) -> str:
        return f"degrees={self.degrees}, p={self.p}, same_on_batch={self.same_on_batch}"

    def forward_parameters(self, batch_shape: Sequence[int] | torch.Size) -> dict[str, torch.Tensor]:
        """Draws the parameters of a batch.

        Args:
            batch_shape: the shape of the batch, (B, C, H, W) (only B is used).

        Returns:
            ``{"degrees": (B,) float64 θ in degrees, "batch_prob": (B,) bool, whether the
            sample is turned}``, on the CPU. The apply flags are drawn first, then the
            angles, each one value per sample (one for all with ``same_on_batch``).
        """
        if len(batch_shape) == 0:
            raise ValueError("batch_shape must start with the batch size B, got an empty shape")
        b = int(batch_shape[0])
        n = 1 if self.same_on_batch else b
        if self.p in (0.0, 1.0):  # decided without a draw, as kornia does
            apply = torch.full((b,), self.p == 1.0)
        else:
            apply = (torch.rand(n, generator=self.generator, dtype=torch.float64) < self.p).expand(b)
        lo, hi = self.degrees
        u = torch.rand(n, generator=self.generator, dtype=torch.float64)
        return {"degrees": (lo + (hi - lo) * u).expand(b).clone(), "batch_prob": apply.clone()}

    def forward(
        self,
        view1: torch.Tensor,
        view2: torch.Tensor | None = None,
        *,
        correspondence: Correspondence,
        params: Mapping[str, torch.Tensor] | None = None,
        masks: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Turns each sample by its θ (where its apply flag is set).

        Args:
            view1: (B, C, H, W) first seed views (angle 0), one object per sample.
            view2: (B, C, H, W) second seed views (angle ``alpha``), or None to warp view 1 alone.
            correspondence: (B, H, W) each sample's correspondences between its seed views.
            params: parameters to replay (``"degrees"`` (B,), optional ``"batch_prob"``
                (B,), default all True), as :meth:`forward_parameters` returns them and
                ``_params`` keeps them; None draws new ones.
            masks: optional (S, B, H, W) foreground masks of the seed views
                (silhouette-aware sampling, see :meth:`NovelViewWarp.apply_maps`).

        Returns:
            (B, C, H, W) augmented views: the novel view at θ where applied, ``view1``
            elsewhere. The parameters used are in ``self._params``.
        """
        v1 = check_float_tensor(view1, "view1")
        check_ndim(v1, "view1", (4,), "(B, C, H, W)")
        b = v1.shape[0]
        params = self.forward_parameters(v1.shape) if params is None else _check_params(params, b)
        self._params = params
        degrees, apply = params["degrees"], params["batch_prob"].to("cpu")
        if bool(apply.all()):
            return self._turn(v1, view2, correspondence, degrees, masks)
        index = apply.nonzero().squeeze(1)
        out = v1.clone()
        if index.numel() == 0:
            return out
        turned = self._turn(
            v1[index.to(v1.device)],
            None if view2 is None else view2[index.to(view2.device)],
            correspondence[index],
            degrees[index.to(degrees.device)],
            None if masks is None else masks[:, index.to(masks.device)],
        )
        return out.index_copy(0, index.to(v1.device), turned)

    def _turn(
        self,
        view1: torch.Tensor,
        view2: torch.Tensor | None,
        correspondence: Correspondence,
        degrees: torch.Tensor,
        masks: torch.Tensor | None,
    ) -> torch.Tensor:
        """All B samples at their own angles, one batched warp: (B, C, H, W)."""
        views = self.warp(view1, view2, correspondence=correspondence, thetas=degrees[:, None], masks=masks)
        return views[:, 0]


def _check_params(params: Mapping[str, torch.Tensor], b: int) -> dict[str, torch.Tensor]:
    """Replayed parameters, checked against the batch size B; batch_prob defaults to all True."""
    if not isinstance(params, Mapping):
        raise TypeError(f"params must be a dict of tensors, got {type(params).__name__}")
    unknown = sorted(set(params) - set(_PARAM_KEYS))
    if unknown or "degrees" not in params:
        raise ValueError(
            f"params must have the key 'degrees' and optionally 'batch_prob', got {sorted(params)}"
        )
    degrees = check_float_tensor(params["degrees"], "params['degrees']")
    apply = params.get("batch_prob", torch.ones(b, dtype=torch.bool))
    if not isinstance(apply, torch.Tensor):
        raise TypeError(f"params['batch_prob'] must be a tensor, got {type(apply).__name__}")
    for name, value in (("degrees", degrees), ("batch_prob", apply)):
        if value.shape != (b,):
            raise ValueError(f"params['{name}'] must have shape (B,) = ({b},), got {tuple(value.shape)}")
    # kornia's batch_prob is a float 0/1 flag; either it or a bool is accepted.
    return {"degrees": degrees, "batch_prob": apply > 0.5}
