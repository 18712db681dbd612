"""Bad input to the Python API of this session's entry points for the method (rejection of
unknown objects, seed masks, the extent, the circle's overlap, the thread policy): each must
raise ValueError or TypeError naming the argument, the constraint and the value, never
another exception, a hang or a silent result (views and backgrounds: test_api_inputs_2.py).
Good input (``GOOD``: a thread count, a calibrated rejection) must be answered right.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import pytest
import torch

from torch_eigview.method import FewViewEigenspace
from torch_eigview.method.rejection import calibrate_rejection
from torch_eigview.scale.thread_policy import default_threads, for_products, idle_cpus, threads
from torch_eigview.synthesis import SynthesisOptions, synthesize_circle, synthesize_views
from torch_eigview.warp.normalize import resolve_extent

from tests.adversarial import files, views
from tests.adversarial.harness import Case, Good, judge, outcome, params


def _seeds() -> torch.Tensor:
    """Two objects' seed views at 0 and 10 degrees (2, 2, 1, 32, 32), rendered."""
    images = views._rendered()
    return torch.stack(
        [
            torch.stack([torch.from_numpy(images[o, a] / 255.0).float()[None] for a in (0, 10)])
            for o in views.OBJECTS
        ]
    )


@functools.cache
def _fitted() -> FewViewEigenspace:
    return FewViewEigenspace(
        3, synth=(-10.0, 10.0, 5.0), reject_rate=0.1, reject_poses=(-10.0, 10.0, 2.5)
    ).fit(_seeds(), [0.0, 10.0])


def _fit(**params: object) -> object:
    return lambda t: FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0), **params).fit(_seeds(), [0.0, 10.0])


REJECTION = [
    Case("reject-rate-0", _fit(reject_rate=0.0), r"reject_rate=0\.0 must be a fraction in \(0, 1\)"),
    Case("reject-rate-1", _fit(reject_rate=1.0), r"reject_rate=1\.0 must be a fraction in \(0, 1\)"),
    Case("reject-rate-nan", _fit(reject_rate=math.nan), r"reject_rate=nan must be a fraction in \(0, 1\)"),
    Case("reject-rate-text", _fit(reject_rate="5%"), r"reject_rate must be a number, got str '5%'"),
    Case(
        "reject-score-bogus",
        _fit(reject_rate=0.1, reject_score="euclid"),
        r"reject_score='euclid' must be one of",
    ),
    Case(
        "reject-poses-reversed",
        _fit(reject_rate=0.1, reject_poses=(10.0, -10.0, 1.0)),
        r"reject_poses must have start <= stop, got start=10\.0, stop=-10\.0",
    ),
    Case(
        "reject-poses-step-0",
        _fit(reject_rate=0.1, reject_poses=(-10.0, 10.0, 0.0)),
        r"reject_poses step must be positive, got 0",
    ),
    Case(
        "reject-poses-tiny-step",
        _fit(reject_rate=0.1, reject_poses=(-10.0, 10.0, 1e-9)),
        r"reject_poses asks for 2e\+10 views per object, more than the limit",
    ),
    Case(
        "reject-poses-gallery-only",
        _fit(reject_rate=0.1, reject_poses=(0.0, 0.0, 1.0)),
        r"reject_poses \(0\.0, 0\.0, 1\.0\) holds gallery angles only",
    ),
    Case(
        "reject-poses-nan",
        _fit(reject_rate=0.1, reject_poses=(math.nan, 10.0, 1.0)),
        r"reject_poses must hold finite angles, got \(nan, 10\.0, 1\.0\)",
    ),
    Case(
        "reject-poses-two-values",
        _fit(reject_rate=0.1, reject_poses=(0.0, 10.0)),
        r"reject_poses must be \(start, stop, step\) .*got \(0\.0, 10\.0\)",
    ),
    Case(
        "reject-without-synth",
        lambda t: FewViewEigenspace(3, synth=None, reject_rate=0.1).fit(_seeds(), [0.0, 10.0]),
        r"reject_rate=0\.1 calibrates on synthesized views: it needs synth",
    ),
    Case(
        "fit-masks-shape",
        lambda t: FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0)).fit(
            _seeds(), [0.0, 10.0], masks=torch.ones(2, 2, 16, 16, dtype=torch.bool)
        ),
        r"masks\[0\] \(of seeds\[0\]\): masks must have shape \(V, H, W\) = \(2, 32, 32\) .*got \(2, 16, 16\)",
    ),
    Case(
        "fit-masks-all-false",
        lambda t: FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0)).fit(
            _seeds(), [0.0, 10.0], masks=torch.zeros(2, 2, 32, 32, dtype=torch.bool)
        ),
        r"masks\[0\]\[0\] is all background",
    ),
    Case(
        "fit-masks-float",
        lambda t: FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0)).fit(
            _seeds(), [0.0, 10.0], masks=torch.rand(2, 2, 32, 32)
        ),
        r"masks\[0\] \(of seeds\[0\]\): masks must be None or a bool tensor",
    ),
    Case(
        "calibrate-rate-nan",
        lambda t: calibrate_rejection(_fitted().recognizer_, _seeds()[0], math.nan),
        r"reject_rate=nan must be a fraction in \(0, 1\)",
    ),
    Case(
        "calibrate-views-shape",
        lambda t: calibrate_rejection(_fitted().recognizer_, torch.rand(3, 1, 8, 8), 0.1),
        r"views must have shape \(B, 1024\) or \(B, \*\(1, 32, 32\)\) like the recognizer's gallery, got \(3, 1, 8, 8\)",
    ),
    Case(
        "calibrate-views-empty",
        lambda t: calibrate_rejection(_fitted().recognizer_, torch.rand(0, 1, 32, 32), 0.1),
        r"views must hold at least one held-out view .*got B=0",
    ),
    Case(
        "calibrate-views-nan",
        lambda t: calibrate_rejection(_fitted().recognizer_, torch.full((3, 1, 32, 32), math.nan), 0.1),
        r"views gave non-finite rejection scores: check them for NaN",
    ),
    Case(
        "calibrate-score-bogus",
        lambda t: calibrate_rejection(_fitted().recognizer_, _seeds()[0], 0.1, "magic"),
        r"score='magic' must be one of",
    ),
    Case(
        "predict-reject-not-bool",
        lambda t: _fitted().recognizer_.predict(_seeds()[0], reject="yes"),
        r"reject must be a bool, got str",
    ),  # type: ignore[arg-type]
    Case(
        "predict-reject-uncalibrated",
        lambda t: (
            FewViewEigenspace(3, synth=(-10.0, 10.0, 5.0))
            .fit(_seeds(), [0.0, 10.0])
            .predict(_seeds()[0], reject=True)
        ),
        r"reject=True needs rejection thresholds, and this recognizer has none",
    ),
    Case(
        "set-rejection-nan",
        lambda t: _fitted().recognizer_.set_rejection(torch.tensor([math.nan, 0.1])),
        r"reject_thresholds must be \(t_dffs, t_difs\), each > 0 or inf, got .*\[nan, ",
    ),
    Case(
        "set-rejection-negative",
        lambda t: _fitted().recognizer_.set_rejection(torch.tensor([-1.0, 0.1])),
        r"reject_thresholds must be \(t_dffs, t_difs\), each > 0 or inf, got .*\[-1\.0, ",
    ),
    Case(
        "set-rejection-shape",
        lambda t: _fitted().recognizer_.set_rejection(torch.tensor([0.1])),
        r"reject_thresholds must be \(t_dffs, t_difs\).*got shape \(1,\)",
    ),
]

SYNTHESIS = [
    Case(
        "options-extent-text",
        lambda t: SynthesisOptions(extent="yes"),
        r"extent must be True, False or 'auto', got 'yes'",
    ),
    Case(
        "options-extent-int",
        lambda t: SynthesisOptions(extent=1),
        r"extent must be True, False or 'auto', got 1",
    ),  # type: ignore[arg-type]
    Case(
        "resolve-extent-text",
        lambda t: resolve_extent("always", torch.ones(2, 8, 8, dtype=torch.bool)),
        r"extent must be True, False or 'auto', got 'always'",
    ),
    Case(
        "resolve-extent-masks-float",
        lambda t: resolve_extent("auto", torch.ones(2, 8, 8)),
        r"masks must be a bool tensor",
    ),
    Case(
        "synth-masks-shape",
        lambda t: synthesize_views(_seeds()[0], 10.0, [5.0], masks=torch.ones(2, 16, 16, dtype=torch.bool)),
        r"masks must have shape \(V, H, W\) = \(2, 32, 32\) to match the seeds, got \(2, 16, 16\)",
    ),
    Case(
        "synth-masks-all-false",
        lambda t: synthesize_views(_seeds()[0], 10.0, [5.0], masks=torch.zeros(2, 32, 32, dtype=torch.bool)),
        r"masks\[0\] is all background",
    ),
    Case(
        "synth-masks-uint8",
        lambda t: synthesize_views(
            _seeds()[0], 10.0, [5.0], masks=torch.full((2, 32, 32), 7, dtype=torch.uint8)
        ),
        r"masks must be None or a bool tensor",
    ),
    Case(
        "circle-overlap-negative",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], 60.0, overlap=-5.0),
        r"overlap=-5 must be in \[0, alpha/2",
    ),
    Case(
        "circle-overlap-nan",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], 60.0, overlap=math.nan),
        r"overlap=nan must be in \[0, alpha/2",
    ),
    Case(
        "circle-overlap-past-alpha",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], 60.0, overlap=500.0),
        r"overlap=500 must be in \[0, alpha/2",
    ),
    Case(
        "circle-step-tiny",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], 1e-9),
        r"step asks for 1\.2e\+11 views per object, more than the limit of \d+.*EIGVIEW_MAX_VIEWS",
    ),
    Case(
        "circle-step-nan",
        lambda t: synthesize_circle(_seeds()[0].repeat(2, 1, 1, 1)[:3], math.nan),
        r"step must be positive, got nan",
    ),
    Case(
        "circle-two-seeds",
        lambda t: synthesize_circle(_seeds()[0], 10.0),
        r"seeds must hold M >= 3 views evenly spaced round the circle, got M=2",
    ),
]

THREADS = [
    Case("threads-0", lambda t: threads(0).__enter__(), r"threads=0 must be >= ?1"),
    Case("threads-negative", lambda t: threads(-2).__enter__(), r"threads=-2 must be >= ?1"),
    Case("threads-text", lambda t: threads("2").__enter__(), r"threads must be an integer, got str '2'"),  # type: ignore[arg-type]
    Case("threads-float", lambda t: threads(2.5).__enter__(), r"threads must be an integer, got float 2\.5"),  # type: ignore[arg-type]
    Case(
        "threads-huge",
        lambda t: threads(10**9).__enter__(),
        r"threads asks for 1e\+09 threads, more than the limit of 1024.*EIGVIEW_MAX_THREADS",
    ),
    Case("products-nan", lambda t: for_products(math.nan).__enter__(), r"flops=nan must be non-negative"),
    Case("products-negative", lambda t: for_products(-1.0).__enter__(), r"flops=-1\.0 must be non-negative"),
    Case("idle-interval-negative", lambda t: idle_cpus(-1.0), r"interval=-1\.0 must be positive"),
    Case("idle-interval-nan", lambda t: idle_cpus(math.nan), r"interval=nan must be positive"),
    Case(
        "idle-interval-huge", lambda t: idle_cpus(1e9), r"interval=1000000000\.0 must be at most 60 seconds"
    ),
    Case(
        "idle-stat-fifo",
        lambda t: idle_cpus(0.01, stat=files.fifo(t / "stat")),
        r"stat='.*stat' must be a regular file",
    ),
]

CASES = REJECTION + SYNTHESIS + THREADS


def _in_threads(n: int | None) -> tuple[int, int, int, int]:
    """(threads before, the count ``threads(n)`` yields, torch's count inside, after)."""
    before = torch.get_num_threads()
    with threads(n) as count:
        inside = torch.get_num_threads()
    return before, count, inside, torch.get_num_threads()


def _threads_set(n: int) -> object:
    """The check of :func:`_in_threads`: ``n`` threads inside, the caller's restored after."""

    def check(out: tuple[int, int, int, int], tmp: Path) -> bool:
        before, count, inside, after = out
        assert count == inside == n and after == before, out
        return True

    return check


def _known(out: list[object], tmp: Path) -> bool:
    """Each object's seed views, with rejection: its own label and pose, known."""
    for result, angle in zip(out, (0.0, 10.0), strict=True):
        assert result.labels.tolist() == [0, 1] and result.poses.tolist() == [angle, angle], result  # type: ignore[attr-defined]
        assert result.known.tolist() == [True, True], result  # type: ignore[attr-defined]
    return True


GOOD = [
    Good("threads-1", lambda t: _in_threads(1), _threads_set(1)),
    Good("threads-2", lambda t: _in_threads(2), _threads_set(2)),
    Good("threads-policy", lambda t: _in_threads(None), _threads_set(default_threads())),
    Good(
        "reject-known-seeds",
        lambda t: [_fitted().predict(_seeds()[:, v], reject=True) for v in (0, 1)],
        _known,
    ),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what


@pytest.mark.parametrize("case", params(GOOD))
def test_good_input_is_answered_right(case: Good, tmp_path: Path) -> None:
    kind, what = judge(case, tmp_path)
    assert kind == "right", what
