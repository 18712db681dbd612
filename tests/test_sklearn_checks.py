"""scikit-learn's own estimator checks on the default-constructed estimators, and the rules
that let the classifier take generic rows: how a row becomes an image without
``image_shape``, and how a label's seeds spanning a half turn or more are fitted."""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("sklearn")

from sklearn.utils.estimator_checks import check_estimator, parametrize_with_checks

from torch_eigview.datasets import AffineCamera, OrthographicCamera, make_object, render_views
from torch_eigview.method import FewViewEigenspace
from torch_eigview.sklearn import EigenspaceKernelPCA, EigenspacePCA, FewViewRecognizerClassifier
from torch_eigview.synthesis import SynthesisOptions


@parametrize_with_checks(
    [
        EigenspacePCA(),
        EigenspaceKernelPCA(),
        FewViewRecognizerClassifier(synth=None),  # the sparse baseline: the rows are the gallery
    ]
)
def test_scikit_learn_checks(estimator: object, check: object) -> None:
    check(estimator)  # type: ignore[operator]


@pytest.mark.slow  # about 300 flows: check_classifiers_train fits 100 seed views per label
@pytest.mark.filterwarnings("ignore::UserWarning")  # 1-pixel-high rows, elevation fallbacks
def test_check_estimator_on_the_default_classifier() -> None:
    """The classifier as constructed by default synthesizes: scikit-learn's rows are its seed views."""
    results = check_estimator(FewViewRecognizerClassifier(), on_fail=None)
    failed = {r["check_name"]: repr(r["exception"]) for r in results if r["status"] == "failed"}
    assert len(results) > 40 and not failed, failed


CAMERA = OrthographicCamera(16)


def _rows(shape: str, angles: list[float], camera: AffineCamera = CAMERA) -> np.ndarray:
    return render_views(make_object(shape), angles, camera).flatten(1).numpy()


def test_rows_become_images_by_a_documented_rule() -> None:
    X = np.concatenate([_rows("egg", [0.0, 10.0]), _rows("head", [0.0, 10.0])])
    y = [0, 0, 1, 1]
    square = FewViewRecognizerClassifier(4, synth=(-10.0, 10.0, 5.0)).fit(X, y)
    shaped = FewViewRecognizerClassifier(4, image_shape=(1, 16, 16), synth=(-10.0, 10.0, 5.0)).fit(X, y)
    assert square.model_.image_shape_ == (1, 16, 16)
    assert torch.equal(square.recognizer_.codes, shaped.recognizer_.codes)
    # One image row of 24 values, not a square: a 1-pixel-high image. The renders are not
    # size-normalized as COIL's images are, so the synthesized views are not either (extent).
    camera = OrthographicCamera(24)
    line = np.concatenate([_rows(s, [0.0, 10.0], camera)[:, 24 * 12 : 24 * 13] for s in ("egg", "head")])
    tests = np.concatenate(
        [_rows(s, [-5.0, 5.0, 15.0], camera)[:, 24 * 12 : 24 * 13] for s in ("egg", "head")]
    )
    clf = FewViewRecognizerClassifier(2, synth=(-10.0, 10.0, 5.0), options=SynthesisOptions(extent=False))
    with pytest.warns(UserWarning, match=r"n_features=24 is not a square.*\(1, 1, 24\).*image_shape"):
        clf.fit(line, y)
    assert clf.model_.image_shape_ == (1, 1, 24)
    assert np.isfinite(clf.model_.recognizer_.codes.numpy()).all()
    assert clf.predict(line).tolist() == y
    assert clf.predict(tests).tolist() == [0, 0, 0, 1, 1, 1]


def test_a_label_needs_two_rows_to_synthesize() -> None:
    X = np.random.default_rng(0).random((3, 16))
    with pytest.raises(ValueError, match=r"every label 2 rows or more.*1 row of label 'b'.*synth=None"):
        FewViewRecognizerClassifier().fit(X, ["a", "a", "b"])


def test_seeds_spanning_a_half_turn_are_fitted_as_runs() -> None:
    angles = [0.0, 60.0, 120.0, 180.0, 240.0]
    X = np.concatenate([_rows("egg", angles), _rows("head", angles)])
    y = np.repeat([0, 1], 5)
    synth, options = (-10.0, 10.0, 10.0), SynthesisOptions(extent=False)
    clf = FewViewRecognizerClassifier(6, image_shape=(1, 16, 16), synth=synth, options=options)
    clf.fit(X, y, angles=angles * 2)
    # Runs of less than 180 degrees sharing their end seeds: 0-120 and 120-240 per label.
    seeds = torch.from_numpy(X).reshape(2, 5, 1, 16, 16)
    runs = [seeds[o, i : i + 3] for o in range(2) for i in (0, 2)]
    run_angles = [angles[i : i + 3] for _ in range(2) for i in (0, 2)]
    reference = FewViewEigenspace(6, synth=synth, options=options).fit(runs, run_angles, [0, 0, 1, 1])
    assert torch.equal(clf.recognizer_.codes, reference.recognizer_.codes)
    assert clf.recognizer_.poses.min() < -90 and clf.recognizer_.poses.max() > 90  # past 180, wrapped
    assert clf.predict(X).tolist() == y.tolist()
