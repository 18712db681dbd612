"""Rejection of unknown objects: the scores a recognizer compares with its thresholds.

A view is taken to be of a known object when it lies close to the eigenspace (its distance
from feature space, DFFS) and close to a gallery view inside it (its distance in feature
space to the nearest gallery view, DIFS). :func:`rejection_score` puts both in units of
their thresholds, so that one limit (1) decides and sweeping that limit gives the ROC;
the thresholds themselves are calibrated from the training views
(:func:`torch_eigview.method.rejection.calibrate_rejection`).
"""

from __future__ import annotations

import math

import torch

from torch_eigview.check import check_float_tensor
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection

__all__ = [
    "NOT_CALIBRATED",
    "check_reject_thresholds",
    "dffs_of",
    "distance_from_feature_space",
    "rejection_score",
    "thresholded_score",
]

NOT_CALIBRATED = (
    "reject=True needs rejection thresholds, and this recognizer has none: calibrate them "
    "(FewViewEigenspace(reject_rate=...), torch_eigview.method.rejection.calibrate_rejection) "
    "or call set_rejection"
)


def rejection_score(dffs: torch.Tensor, difs: torch.Tensor, inverse: torch.Tensor) -> torch.Tensor:
    """How far views lie past the rejection thresholds: a view is known when its score is <= 1.

    ``max(dffs / t_dffs, difs / t_difs)``, as products with the reciprocals so that an
    infinite threshold (reciprocal 0) leaves its score out and an exported graph holds
    finite constants only. Export-friendly: no data-dependent branch.

    Args:
        dffs: (B,) distances from feature space.
        difs: (B,) distances to the nearest gallery view.
        inverse: (2,) ``(1 / t_dffs, 1 / t_difs)``, each >= 0.

    Returns:
        (B,) scores in units of the thresholds.

    Example:
        >>> rejection_score(torch.tensor([0.5, 0.1]), torch.tensor([0.2, 0.6]), torch.tensor([0.0, 2.5]))
        tensor([0.5000, 1.5000])
    """
    return torch.maximum(dffs * inverse[0], difs * inverse[1])


def distance_from_feature_space(v: torch.Tensor, mean: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """DFFS: the distance of prepared views from a linear eigenspace with orthonormal components.

    ``sqrt(|v − mean|² − |z|²)``, the residual left after projecting (Pythagoras: the
    components are orthonormal, so ``|z|`` is the length of the part inside the space).

    Args:
        v: (B, N) views as the eigenspace sees them (flattened, unit-norm if the layer is).
        mean: (N,) the mean view.
        z: (B, k) their coordinates.

    Returns:
        (B,) distances, >= 0.
    """
    sq = (v - mean).square().sum(dim=1) - z.square().sum(dim=1)
    return sq.clamp_min(0).sqrt()


def check_reject_thresholds(thresholds: object, linear: bool) -> list[float]:
    """``(t_dffs, t_difs)`` checked: a (2,) float tensor, each > 0 or inf, not both inf; a
    finite ``t_dffs`` only when the projection is ``linear`` (kernel PCA has no residual here).

    Returns:
        The two thresholds as floats.

    Raises:
        TypeError: not a float tensor.
        ValueError: a bad shape or value.
    """
    check_float_tensor(thresholds, "reject_thresholds")
    assert isinstance(thresholds, torch.Tensor)
    values = thresholds.detach().to("cpu", torch.float64).flatten().tolist()
    if tuple(thresholds.shape) != (2,) or any(math.isnan(v) or v <= 0 for v in values):
        raise ValueError(
            "reject_thresholds must be (t_dffs, t_difs), each > 0 or inf, got "
            f"shape {tuple(thresholds.shape)} values {values}"
        )
    if all(math.isinf(v) for v in values):
        raise ValueError(f"reject_thresholds={values} must hold at least one finite threshold")
    if math.isfinite(values[0]) and not linear:
        raise ValueError(
            f"reject_thresholds={values}: a finite t_dffs needs a linear EigenProjection, this "
            "recognizer's projection is a kernel projection (use inf)"
        )
    return values


def dffs_of(projection: EigenProjection | KernelProjection, x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """DFFS of views ``x`` (B, C, H, W) or (B, N) with coordinates ``z`` (B, k) in ``projection``;
    (B,) NaN for a kernel projection, whose feature space this does not measure."""
    if not isinstance(projection, EigenProjection):
        return z.new_full(z.shape[:1], math.nan)
    return distance_from_feature_space(projection.prepare(x), projection.mean, z)


def thresholded_score(
    projection: EigenProjection | KernelProjection,
    x: torch.Tensor,
    z: torch.Tensor,
    difs: torch.Tensor,
    thresholds: torch.Tensor,
) -> torch.Tensor:
    """:func:`rejection_score` of views ``x`` with coordinates ``z`` (B, k) and nearest-view
    distances ``difs`` (B,), computing DFFS only when its threshold is finite (an unused
    one, NaN for a kernel projection, would otherwise win the maximum)."""
    if math.isfinite(float(thresholds[0])):
        dffs = dffs_of(projection, x, z)
    else:
        dffs = torch.zeros_like(difs)
    return rejection_score(dffs, difs, 1 / thresholds)
