"""The paper's method as a scikit-learn classifier: :class:`FewViewRecognizerClassifier`."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import torch
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_array, check_is_fitted, validate_data

from torch_eigview.check import check_image_shape, check_number
from torch_eigview.geometry.angles import AROUND_SEEDS
from torch_eigview.method import FewViewEigenspace
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.sklearn._common import FLOATS, to_numpy, to_tensor
from torch_eigview.synthesis import SynthesisOptions

__all__ = ["FewViewRecognizerClassifier"]


def _default_shape(n_features: int, warn: bool) -> tuple[int, int, int]:
    """The image a row of ``n_features`` values is without ``image_shape``: square grey, or one line."""
    side = math.isqrt(n_features)
    if side * side == n_features:
        return (1, side, side)
    if warn:
        warnings.warn(
            f"image_shape is None and n_features={n_features} is not a square: each row is taken as a "
            f"1-pixel-high image (1, 1, {n_features}); pass image_shape=(C, H, W) if the rows are images",
            UserWarning,
            stacklevel=3,
        )
    return (1, 1, n_features)


def _seed_runs(rows: list[np.ndarray], poses: np.ndarray, classes: np.ndarray) -> list[np.ndarray]:
    """Each label's rows split into runs of seeds spanning less than 180°, sharing end seeds.

    ``synthesize_views`` takes the seeds of less than a half turn; each of its seed pairs
    synthesizes only its own sector, so a run ending where the next begins loses nothing.
    """
    runs = []
    for label, r in zip(classes, rows, strict=True):
        if r.size < 2:
            raise ValueError(
                f"y must give every label 2 rows or more to synthesize views from (synth is not None), "
                f"got 1 row of label {np.asarray(label).item()!r}; use synth=None to fit the rows alone"
            )
        gaps = np.abs(np.diff(poses[r]))
        if (gaps >= 180.0).any():
            i = int(np.argmax(gaps >= 180.0))
            raise ValueError(
                f"angles must put consecutive rows of a label less than 180 degrees apart to synthesize "
                f"between them, got {poses[r[i]]} and {poses[r[i + 1]]} for label {np.asarray(label).item()!r}"
            )
        start = 0
        while start < r.size - 1:
            stop = start + 1  # a run holds one seed pair at least
            while stop + 1 < r.size and abs(poses[r[stop + 1]] - poses[r[start]]) < 180.0:
                stop += 1
            runs.append(r[start : stop + 1])
            start = stop
    return runs


class FewViewRecognizerClassifier(ClassifierMixin, BaseEstimator):
    """The paper's method (:class:`~torch_eigview.method.FewViewEigenspace`) as a classifier.

    ``fit(X, y)`` takes the seed views: each row of ``X`` is one image flattened row-major
    from ``image_shape`` (C, H, W), ``y`` its object's label. The rows of one label are that
    object's seed views, in order of appearance, at the angles ``angles`` (a fit parameter:
    one angle in degrees per row; ``GridSearchCV`` and ``Pipeline`` pass it on, e.g.
    ``pipe.fit(X, y, clf__angles=a)``) or, without it, at 0, α, 2α, … (``alpha``). Each
    object's views over ``synth`` are synthesized from its seeds, one eigenspace is fitted
    over all of them, and ``predict`` gives a row the label of its nearest gallery view
    (``predict_pose``: that view's pose).

    How rows become images: with ``image_shape`` given, each row is a (C, H, W) image;
    without it, a row of n = s² features is a (1, s, s) grey image and any other row a
    1-pixel-high image (1, 1, n), one line along the turntable's rows (a warning says
    so: pass ``image_shape`` for colour or non-square images). The seeds of one label
    must span less than a half turn for the warp (``synthesize_views``); seeds that
    span more, e.g. all around the object, are fitted as consecutive runs that each
    span less than 180° and share their end seeds, every run synthesizing its own
    views over ``synth`` (the default extrapolates 20° past each run's end seeds, so
    neighbouring runs overlap there). A label needs two rows or more to synthesize from. The default
    ``options`` size-normalize each synthesized view as COIL's processed images are
    (``extent``): rows not normalized that way want ``SynthesisOptions(extent=False)``.

    With ``synth=None`` nothing is synthesized: the gallery is the rows themselves, any
    number per label (the experiments' ``sparse`` baseline; images or any other
    features, ``image_shape`` optional).

    Args:
        n_components: k (int >= 1), an energy fraction in (0, 1), or None: every component.
        image_shape: (C, H, W) of the images, or None: taken from n_features as above.
        alpha: angle in degrees between consecutive seed views of a label, without ``angles``.
        synth, options, unit_norm, kernel, gamma, synth_follows_seeds: as ``FewViewEigenspace``'s.

    Attributes:
        classes_: the labels, sorted.
        model_: the fitted ``FewViewEigenspace`` (its gallery labels index ``classes_``).
        recognizer_: its ``NearestNeighborRecognizer``.

    Example:
        >>> X = np.random.default_rng(0).random((6, 64))
        >>> clf = FewViewRecognizerClassifier(synth=None).fit(X, [0, 0, 1, 1, 2, 2])
        >>> clf.predict(X).tolist()
        [0, 0, 1, 1, 2, 2]
    """

    def __init__(
        self,
        n_components: int | float | None = None,
        *,
        image_shape: tuple[int, int, int] | None = None,
        alpha: float = 10.0,
        synth: tuple[float, float, float] | str | None = AROUND_SEEDS,
        options: SynthesisOptions | None = None,
        unit_norm: bool = True,
        kernel: str | None = None,
        gamma: float | str | None = None,
        synth_follows_seeds: bool = True,
    ) -> None:
        self.n_components = n_components
        self.image_shape = image_shape
        self.alpha = alpha
        self.synth = synth
        self.options = options
        self.unit_norm = unit_norm
        self.kernel = kernel
        self.gamma = gamma
        self.synth_follows_seeds = synth_follows_seeds

    def fit(self, X: Any, y: Any, angles: Any = None) -> FewViewRecognizerClassifier:
        """Fits on seed views ``X`` (n_samples, C*H*W) of the objects ``y`` (n_samples,).

        Args:
            X: the seed views, flattened; n_samples >= 2.
            y: their labels.
            angles: (n_samples,) their angles in degrees, or None: 0, α, 2α, … per label.

        Returns:
            self, fitted.
        """
        X, y = validate_data(self, X, y, dtype=FLOATS, ensure_min_samples=2)
        check_classification_targets(y)
        self.classes_, index = np.unique(y, return_inverse=True)
        n_features = X.shape[1]
        if self.unit_norm is True and n_features == 1:
            raise ValueError(
                "unit_norm=True needs 2 features or more: one value scales to ±1, got n_features = 1"
            )
        shape = check_image_shape(self.image_shape, n_features, "image_shape")
        if shape is None:
            shape = _default_shape(n_features, warn=self.synth is not None)
        poses = self._angles(angles, index)
        views = to_tensor(X).reshape(-1, *shape)
        rows = [np.flatnonzero(index == c) for c in range(len(self.classes_))]
        if self.synth is not None:
            rows = _seed_runs(rows, poses, self.classes_)
        # Every parameter but the two that say how rows become seed views is FewViewEigenspace's.
        params = {k: v for k, v in self.get_params().items() if k not in ("image_shape", "alpha")}
        model = FewViewEigenspace(**params)
        seeds = [views[torch.from_numpy(r)] for r in rows]
        labels = [int(index[r[0]]) for r in rows]
        self.model_ = model.fit(seeds, [poses[r].tolist() for r in rows], labels)
        self.recognizer_ = model.recognizer_
        return self

    def _angles(self, angles: Any, index: np.ndarray) -> np.ndarray:
        """(n_samples,) float64 angle of each row: ``angles``, or its rank within its label times α."""
        if angles is None:
            alpha = check_number(self.alpha, "alpha")
            rank = np.zeros(index.shape[0], dtype=np.int64)
            for c in np.unique(index):
                rank[index == c] = np.arange(int((index == c).sum()))
            return rank * alpha
        out = check_array(angles, ensure_2d=False, dtype=np.float64)
        if out.shape != index.shape:
            raise ValueError(
                f"angles must have shape ({index.shape[0]},), one per row of X, got shape {out.shape}"
            )
        return out

    def _recognize(self, X: Any) -> Any:
        check_is_fitted(self)
        X = validate_data(self, X, dtype=FLOATS, reset=False)
        return self.model_.predict(to_tensor(X).to(self.recognizer_.codes.dtype))

    def predict(self, X: Any) -> np.ndarray:
        """(n_samples,) the label (of ``classes_``) of each row's nearest gallery view."""
        labels = to_numpy(self._recognize(X).labels)
        return self.classes_[labels]

    def predict_pose(self, X: Any) -> np.ndarray:
        """(n_samples,) the pose in degrees of each row's nearest gallery view."""
        return to_numpy(self._recognize(X).poses)

    def to_module(self) -> EigenProjection | KernelProjection:
        """The frozen layer that projects (B, C, H, W) views into the eigenspace."""
        check_is_fitted(self)
        return self.model_.to_module()
