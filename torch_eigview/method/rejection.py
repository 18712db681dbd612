"""Calibrating the rejection of unknown objects from the training views alone.

A recognizer answers every view with the nearest gallery label; a view of an object it
was never shown should be answered "unknown" instead. The thresholds that decide are set
from views of the *known* objects that are not in the gallery: views synthesized from each
object's seed views at poses held out from the gallery (:class:`FewViewEigenspace` with
``reject_rate`` makes them), or any held-out real views. The threshold on a score is the
``1 − reject_rate`` quantile of those views' scores, so that about ``reject_rate`` of the
known views met at those poses are rejected.

Which poses: the ones at which known objects will be met. A view far past the gallery's
range lies far from every gallery view, so held-out views only between gallery poses (0.5°
from the nearest) give a threshold that rejects most real views 20° past it (measured on
COIL-20, objects 1–10, seeds at 0° and 10°, gallery −20°..20°: views calibrated between
gallery poses gave t_difs = 0.02, the real known views' median DIFS at −45°..45° is 0.10).
The poses the gallery holds are left out, which weighs the far poses more than a uniform
spread of known views would. Counting every pose alike (a gallery pose replaced by its
mid-pose) was measured too and not taken: on COIL-20 (objects 1–10 known, seeds ``c`` and
``c + 10``, eight centres ``c``, asked 5 %) the real known views rejected over
``reject_poses``' default range came to a median of 6.3 % against 5.3 % as done here, and
per centre from 4.7 % to 23.7 % against 3.2 % to 13.7 %. The spread over the centres is
the larger error: the synthesized views lie nearer to or farther from the gallery than the
real ones at the same pose, and two seed views cannot measure by how much
(``examples/diagnostics/rejection_split.py``). The scores
(:mod:`torch_eigview.nn.rejection`) are DIFS, the distance to the nearest gallery view,
DFFS, the residual off the eigenspace, or both. :func:`estimate_reject_rate` is the
calibration's own estimate of its rate: each object's held-out views judged by the
thresholds of the others'.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from torch_eigview.check import check_choice, check_float_tensor, check_ndim, check_number
from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = [
    "REJECT_SCORES",
    "calibrate_rejection",
    "check_reject_rate",
    "distance_resolution",
    "estimate_reject_rate",
]

REJECT_SCORES = ("difs", "dffs", "both")


def check_reject_rate(rate: object, name: str = "reject_rate") -> float:
    """A fraction of known views one accepts to lose, in (0, 1)."""
    value = check_number(rate, name)
    if not 0.0 < value < 1.0:
        raise ValueError(f"{name}={value!r} must be a fraction in (0, 1) of the known views to reject")
    return value


def distance_resolution(codes: torch.Tensor) -> float:
    """The rounding error of the recognizer's distances for gallery codes ``codes`` (G, k).

    Both scores are square roots of a difference of squared norms (``|z|² − 2 z·c + |c|²``,
    ``|v − mean|² − |z|²``), whose rounding error is a few ``eps·|c|²``; the distance of a
    view to itself therefore comes out as large as ``sqrt(8 eps)·max|c|`` (measured on the
    synthetic renderer in float32: 1e-4 for the seed views, which are gallery views). A
    threshold at or below it cannot tell a held-out view from a gallery view.
    """
    if codes.numel() == 0:
        return 0.0
    scale = float(codes.detach().double().norm(dim=1).max())
    return math.sqrt(8 * torch.finfo(codes.dtype).eps) * scale


def _check_views(recognizer: NearestNeighborRecognizer, views: object) -> None:
    """Held-out views: a non-empty float batch of the gallery's view size (named ``views``)."""
    views = check_float_tensor(views, "views")
    check_ndim(views, "views", (2, 4), "(B, N) or (B, C, H, W)")
    if views.shape[0] == 0:
        raise ValueError("views must hold at least one held-out view to calibrate on, got B=0")
    proj = recognizer.projection
    shape = getattr(proj, "image_shape", None)
    if views[0].numel() != proj.in_features or (
        views.ndim == 4 and shape is not None and views.shape[1:] != shape
    ):
        raise ValueError(
            f"views must have shape (B, {proj.in_features}) or (B, *{tuple(shape or ())}) like the "
            f"recognizer's gallery, got {tuple(views.shape)}"
        )


def calibrate_rejection(
    recognizer: NearestNeighborRecognizer,
    views: torch.Tensor,
    reject_rate: float = 0.05,
    score: str = "difs",
) -> torch.Tensor:
    """Sets ``recognizer``'s rejection thresholds from held-out views of its known objects.

    Args:
        recognizer: the fitted recognizer; its thresholds are replaced.
        views: (B, C, H, W) or (B, N) views of the gallery's objects that are not gallery
            views (the projection's dtype), at the poses the recognizer will meet them.
        reject_rate: the fraction of those views to reject, in (0, 1): each threshold is
            the ``1 − reject_rate`` quantile of its score.
        score: ``"difs"`` (distance to the nearest gallery view), ``"dffs"`` (distance
            from feature space; linear eigenspace only) or ``"both"``: a view is known
            when both stay within thresholds proportional to their own quantiles,
            scaled together so that ``reject_rate`` of the views are rejected.

    Returns:
        The (2,) thresholds ``(t_dffs, t_difs)`` now in ``recognizer.reject_thresholds``
        (``inf`` for a score left out).

    Raises:
        TypeError: ``recognizer`` is not a :class:`NearestNeighborRecognizer`, or ``views``
            not a float tensor.
        ValueError: a bad ``reject_rate`` or ``score``; no views; non-finite scores; a
            threshold within the distances' rounding error (:func:`distance_resolution`):
            the views are gallery views, whose DIFS is 0.

    Example:
        >>> from torch_eigview.nn import EigenProjection
        >>> proj = EigenProjection(torch.zeros(3), torch.eye(3)[:2])
        >>> rec = NearestNeighborRecognizer.from_views(proj, torch.eye(3)[:2], torch.tensor([0, 1]), torch.zeros(2))
        >>> held_out = torch.tensor([[0.9, 0.1, 0.0], [0.1, 0.8, 0.1]])
        >>> t = calibrate_rejection(rec, held_out, reject_rate=0.5)
        >>> rec.predict(torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), reject=True).known.tolist()
        [True, False]
    """
    rate = check_reject_rate(reject_rate)
    dffs, difs = _scores(recognizer, views, score)
    t_dffs, t_difs = _thresholds(dffs, difs, rate, score)
    floor = distance_resolution(recognizer.codes)
    if t_dffs <= floor or t_difs <= floor:
        raise ValueError(
            f"the calibrated thresholds (t_dffs={t_dffs:.3g}, t_difs={t_difs:.3g}) must exceed the "
            f"rounding error of the distances ({floor:.3g}): the views' {score} scores are 0 to "
            f"rounding at the {1.0 - rate:.3g} quantile, so they are gallery views (or lie in the "
            "eigenspace); calibrate on views held out from the gallery"
        )
    thresholds = torch.tensor([t_dffs, t_difs], dtype=recognizer.codes.dtype, device=recognizer.codes.device)
    recognizer.set_rejection(thresholds)
    return thresholds


def estimate_reject_rate(
    recognizer: NearestNeighborRecognizer,
    views: torch.Tensor,
    groups: torch.Tensor | Sequence[int],
    reject_rate: float = 0.05,
    score: str = "difs",
) -> float:
    """The calibration's own estimate of the fraction of known views it rejects.

    Each group's views (one object's, say) are judged by the thresholds
    :func:`calibrate_rejection` sets from the other groups' views, as a known view the
    calibration never saw is judged; the estimate is the fraction of all views rejected
    so. It differs from ``reject_rate`` by how much the thresholds depend on which
    objects they were set on. ``recognizer``'s own thresholds are left as they are.

    Args:
        recognizer: the fitted recognizer.
        views: (B, C, H, W) or (B, N) held-out views of its known objects, as for
            :func:`calibrate_rejection`.
        groups: (B,) integer group of each view; at least two groups.
        reject_rate: the fraction asked for, in (0, 1).
        score: ``"difs"``, ``"dffs"`` or ``"both"``, as for :func:`calibrate_rejection`.

    Returns:
        The estimated fraction of known views rejected, in [0, 1].

    Raises:
        TypeError: a wrong type (the message names the argument).
        ValueError: a bad ``reject_rate`` or ``score``; no views; ``groups`` not one
            integer per view, or fewer than two groups.

    Example:
        >>> from torch_eigview.nn import EigenProjection
        >>> proj = EigenProjection(torch.zeros(3), torch.eye(3)[:2])
        >>> rec = NearestNeighborRecognizer.from_views(proj, torch.eye(3)[:2], torch.tensor([0, 1]), torch.zeros(2))
        >>> held = torch.tensor([[1.0, 0.1 * i, 0.0] for i in range(1, 9)])
        >>> estimate_reject_rate(rec, held, [0, 1] * 4, reject_rate=0.25)  # 3 of 8 each by the other half's
        0.375
    """
    rate = check_reject_rate(reject_rate)
    dffs, difs = _scores(recognizer, views, score)
    if isinstance(groups, torch.Tensor):
        if groups.is_floating_point() or groups.is_complex() or groups.dtype == torch.bool:
            raise TypeError(f"groups must hold integers, got a {groups.dtype} tensor")
        group = groups.detach().to("cpu", torch.int64).flatten()
    elif isinstance(groups, Sequence) and not isinstance(groups, str):
        if not all(isinstance(g, int) and not isinstance(g, bool) for g in groups):
            raise TypeError("groups must be a sequence of integers, one per view")
        group = torch.tensor(list(groups), dtype=torch.int64)
    else:
        raise TypeError(f"groups must be a tensor or sequence of integers, got {type(groups).__name__}")
    shape = tuple(groups.shape) if isinstance(groups, torch.Tensor) else (len(groups),)
    if shape != (difs.numel(),):
        raise ValueError(f"groups must hold one group per view, shape ({difs.numel()},), got shape {shape}")
    names = group.unique()
    if names.numel() < 2:
        raise ValueError(
            f"groups must hold at least two groups to judge each by the others' thresholds, got {names.tolist()}"
        )
    rejected = 0
    for g in names:
        mine = group == g
        t_dffs, t_difs = _thresholds(dffs[~mine], difs[~mine], rate, score)
        rejected += int(((dffs[mine] > t_dffs) | (difs[mine] > t_difs)).sum())
    return rejected / difs.numel()


def _scores(
    recognizer: NearestNeighborRecognizer, views: torch.Tensor, score: str
) -> tuple[torch.Tensor, torch.Tensor]:
    """The views' ``(dffs, difs)`` in float64, every argument checked (names each)."""
    if not isinstance(recognizer, NearestNeighborRecognizer):
        raise TypeError(f"recognizer must be a NearestNeighborRecognizer, got {type(recognizer).__name__}")
    check_choice(score, "score", REJECT_SCORES)
    _check_views(recognizer, views)
    if score != "difs" and not hasattr(recognizer.projection, "mean"):
        raise ValueError(
            f"score={score!r} needs the distance from feature space of a linear eigenspace; this "
            f"recognizer's projection is a {type(recognizer.projection).__name__}: use score='difs'"
        )
    with torch.no_grad():
        dffs, difs = (s.double() for s in recognizer.novelty_scores(views))
    if not bool(torch.isfinite(difs).all()) or (score != "difs" and not bool(torch.isfinite(dffs).all())):
        raise ValueError(
            "views gave non-finite rejection scores: check them for NaN, infinite or huge values"
        )
    return dffs, difs


def _thresholds(dffs: torch.Tensor, difs: torch.Tensor, rate: float, score: str) -> tuple[float, float]:
    """``(t_dffs, t_difs)`` that reject ``rate`` of the views with these scores (inf: unused)."""
    q = 1.0 - rate
    t_dffs, t_difs = math.inf, math.inf
    if score == "dffs":
        t_dffs = float(torch.quantile(dffs, q))
    elif score == "difs":
        t_difs = float(torch.quantile(difs, q))
    else:
        s_dffs, s_difs = float(torch.quantile(dffs, q)), float(torch.quantile(difs, q))
        if s_dffs > 0 and s_difs > 0:
            scale = float(torch.quantile(torch.maximum(dffs / s_dffs, difs / s_difs), q))
            t_dffs, t_difs = scale * s_dffs, scale * s_difs
        else:
            t_dffs, t_difs = s_dffs, s_difs
    return t_dffs, t_difs
