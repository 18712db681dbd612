"""How seed views become novel views: :class:`SynthesisOptions`, shared by the seed pairs'
geometry (:mod:`~torch_eigview.synthesis.seed_pairs`) and the warp (:mod:`~torch_eigview.synthesis.views`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from torch_eigview.check import check_number, check_positive
from torch_eigview.geometry.flow import METHODS as FLOW_METHODS
from torch_eigview.warp.base import BLENDS

__all__ = ["SynthesisOptions"]

_FAST_TVL1 = {"num_warp": 3, "num_iter": 5}


@dataclass(frozen=True)
class SynthesisOptions:
    """How seed views become novel views.

    Attributes:
        flow: the correspondences: ``"guided"`` (the default), the row matcher's matches
            over the whole epipolar range refined by TV-L1
            (:func:`~torch_eigview.geometry.guided_flow.guided_tvl1`), which follows the
            large displacements of seeds far apart in angle; TV-L1 optical flow alone,
            ``"tvl1"`` (in torch, batched) or ``"tvl1-skimage"`` (scikit-image's, the
            reference); scikit-image's ``"ilk"``; or ``"rows"``, semi-global matching along
            the epipolar lines alone (:func:`~torch_eigview.geometry.row_matcher.match_rows`).
            ``"guided"`` and ``"rows"`` are given each pair's α and ``center``.
        threshold: forward–backward consistency tolerance in pixels.
        elevation: camera elevation in degrees (0: the paper's orthographic camera, rows
            stay rows), or ``"auto"`` to measure it per seed pair from the vertical flow; a
            pair whose flow gives no trusted foreground match, or a fit at
            ``MAX_AUTO_ELEVATION`` or beyond (saturated), falls back to 0 with an
            :class:`ElevationFallbackWarning`.
        extent: size-normalize each synthesized view as the data set's images are (COIL's
            processed set is): True, False or ``"auto"``
            (:func:`~torch_eigview.warp.normalize.resolve_extent`).
        background: intensity below which a pixel is background (``extent``, elevation fit).
        center: column of the rotation axis, default the image's centre column.
        max_stretch: see :class:`~torch_eigview.warp.novel_view.NovelViewWarp`.
        flow_options: keyword arguments for the flow function (TV-L1's ``num_warp``,
            ``num_iter``, ``tol``, ``prefilter``, …; the same names for the torch and the
            scikit-image TV-L1; the guided flow takes TV-L1's, the row matcher's
            ``depth``, ``elevation``, ``cost``, ``patch``, ``p1``, ``p2``, and its own
            ``prior_side``). By default TV-L1 (alone or in the guided flow) runs 3 warps of
            5 iterations (scikit-image's defaults are 5 and 10): 15 fixed-point steps per
            pyramid level instead of 50, and on COIL-20 as accurate (see the README).
        blend: how the two seeds of a pair share the pixels both see, ``"linear"`` or
            ``"nearest"`` (see :class:`~torch_eigview.warp.novel_view.NovelViewWarp`).
        silhouette: silhouette-aware sampling: only the seeds' foreground pixels
            (``background``) enter a synthesized pixel, renormalized, and a pixel less
            than half covered by them is background (``NovelViewWarp.apply_maps`` with
            ``masks``); off, a silhouette pixel mixes object and background. The mask is
            ``synthesize_views``'s ``masks``, else the ``background`` threshold (then
            object pixels darker than it count as background).
    """

    flow: str = "guided"
    threshold: float = 1.0
    elevation: float | str = "auto"
    extent: bool | str = "auto"
    background: float = 0.05
    center: float | None = None
    max_stretch: float = 3.0
    flow_options: dict[str, object] | None = None
    blend: str = "linear"
    silhouette: bool = False

    def flow_kwargs(self, alpha: float | None = None) -> dict[str, object]:
        """Keyword arguments for the flow function: ``flow_options``, else a fast preset.

        With ``alpha`` (a seed pair's angle in degrees), the epipolar flows (``"rows"``,
        ``"guided"``) also get the angle, ``center`` and a given ``elevation`` (the row
        matcher searches its own for ``"auto"``): the arguments the synthesis runs them with.
        """
        kwargs: dict[str, object] = (
            dict(self.flow_options)
            if self.flow_options is not None
            else dict(_FAST_TVL1)
            if self.flow in ("tvl1", "tvl1-skimage", "guided")
            else {}
        )
        if alpha is None or self.flow not in ("rows", "guided"):
            return kwargs
        given = {} if self.elevation == "auto" else {"elevation": self.elevation}
        return {**given, **kwargs, "alpha": alpha, "center": self.center}

    def __post_init__(self) -> None:
        if self.flow not in FLOW_METHODS:
            raise ValueError(f"flow must be one of {FLOW_METHODS}, got {self.flow!r}")
        if self.flow_options is not None:
            if not isinstance(self.flow_options, dict):
                raise TypeError(
                    f"flow_options must be a dict or None, got {type(self.flow_options).__name__}"
                )
            taken = sorted({"alpha", "center", "threshold"} & set(self.flow_options))
            if taken:
                raise ValueError(
                    f"flow_options must not hold {taken}: each seed pair's angle, SynthesisOptions.center "
                    f"and SynthesisOptions.threshold are passed to the flow"
                )
        if isinstance(self.elevation, str):
            if self.elevation != "auto":
                raise ValueError(f"elevation must be a number of degrees or 'auto', got {self.elevation!r}")
        elif not abs(check_number(self.elevation, "elevation")) < 90:  # NaN fails too
            raise ValueError(f"elevation={self.elevation!r} must be an angle in degrees in (-90, 90)")
        if self.extent != "auto" and not isinstance(self.extent, bool):
            raise ValueError(f"extent must be True, False or 'auto', got {self.extent!r}")
        if not isinstance(self.silhouette, bool):
            raise TypeError(f"silhouette must be a bool, got {type(self.silhouette).__name__}")
        if self.blend not in BLENDS:
            raise ValueError(f"blend must be one of {BLENDS}, got {self.blend!r}")
        check_positive(self.threshold, "threshold")
        if not check_number(self.max_stretch, "max_stretch") > 0:  # inf: no depth jumps
            raise ValueError(f"max_stretch={self.max_stretch!r} must be a number > 0")
        if not math.isfinite(check_number(self.background, "background")):
            raise ValueError(f"background={self.background!r} must be finite")
        if self.center is not None and not math.isfinite(check_number(self.center, "center")):
            raise ValueError(f"center={self.center!r} must be finite or None")
