"""The gallery range of the fitting APIs: 20 degrees past both end seeds by default, the
given ``--synth`` / ``synth`` range otherwise, and the checks that name the argument."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torch_eigview.apps.seed_plan import SeedPlan, held_out_thetas, reject_poses, seed_plan, synth_record
from torch_eigview.geometry.angles import AROUND_SEEDS, SEED_MARGIN, angle_range, around_seeds, off_gallery
from torch_eigview.method import FewViewEigenspace
from torch_eigview.method.inputs import Params, check_synth
from torch_eigview.synthesis import SynthesisOptions


@pytest.mark.parametrize(
    ("steps", "want"),
    [
        ([10.0], (-20.0, 30.0)),  # two seeds 10 apart: -20..30, symmetric about the seeds
        ([30.0], (-20.0, 50.0)),  # the paper's -20..20 would leave the second seed out
        ([-30.0], (-50.0, 20.0)),  # seeds listed the other way round
        ([10.0, 10.0], (-20.0, 40.0)),
        ([10.0, 15.0], (-20.0, 45.0)),
        ([20.0, -5.0], (-20.0, 40.0)),  # the range holds every seed, not just the last
        ([30.0, -40.0], (-30.0, 50.0)),
    ],
)
def test_around_seeds_extends_past_both_end_seeds(steps: list[float], want: tuple[float, float]) -> None:
    start, stop, step = around_seeds(steps)
    assert (start, stop, step) == (*want, 1.0)
    seeds = [0.0, *(sum(steps[: i + 1]) for i in range(len(steps)))]
    assert start == min(seeds) - SEED_MARGIN and stop == max(seeds) + SEED_MARGIN


def test_seed_plan_default_and_given_ranges() -> None:
    assert seed_plan([0.0, 30.0], None, None, None).thetas == angle_range(-20.0, 50.0, 1.0, "t")
    assert seed_plan([0.0, 330.0], None, None, None).thetas == angle_range(-50.0, 20.0, 1.0, "t")
    assert seed_plan([0.0, 10.0, 20.0], None, None, None).thetas == angle_range(-20.0, 40.0, 1.0, "t")
    # --synth as given keeps its meaning: from the first seed, each further seed extending it.
    assert seed_plan([0.0, 30.0], None, None, (-20.0, 20.0, 2.0)).thetas == angle_range(-20.0, 20.0, 2.0, "t")
    assert seed_plan([0.0, 10.0, 20.0], None, None, (-20.0, 20.0, 1.0)).thetas == angle_range(
        -20.0, 30.0, 1.0, "t"
    )
    circle = seed_plan(None, 8, 0.0, None)
    assert circle.thetas is None and circle.step == 1.0


def test_synth_record_is_the_range_the_gallery_holds() -> None:
    plan = seed_plan([0.0, 30.0], None, None, None)
    assert synth_record(None, plan) == [-20.0, 50.0, 1.0]
    assert synth_record([-20.0, 20.0, 2.0], seed_plan([0.0, 30.0], None, None, (-20.0, 20.0, 2.0))) == [
        -20.0,
        20.0,
        2.0,
    ]
    circle = SeedPlan([0.0, 90.0, 180.0, 270.0], 0.0, 90.0, None, 5.0)
    assert synth_record(None, circle) == [0.0, 355.0, 5.0]


def test_params_thetas_around_the_seeds() -> None:
    params = Params(15, AROUND_SEEDS, SynthesisOptions(), True, None, None, True, 4096)
    assert params.thetas([10.0]) == angle_range(-20.0, 30.0, 1.0, "t")
    assert params.thetas([12.0, 12.0]) == angle_range(-20.0, 44.0, 1.0, "t")
    # synth_follows_seeds shapes a given range only.
    given = Params(15, (-20.0, 20.0, 1.0), SynthesisOptions(), True, None, None, False, 4096)
    assert given.thetas([12.0, 12.0]) == angle_range(-20.0, 20.0, 1.0, "t")


def test_check_synth_names_the_argument() -> None:
    assert check_synth(AROUND_SEEDS, around=True) == AROUND_SEEDS
    assert check_synth(None, around=True) is None
    with pytest.raises(
        ValueError,
        match=r"synth must be \(start, stop, step\) in degrees, 'around-seeds', 'circle', a Circle or None, got 'around'",
    ):
        check_synth("around", around=True)
    with pytest.raises(
        ValueError, match=r"reject_poses must be \(start, stop, step\) in degrees, got 'around-seeds'"
    ):
        check_synth(AROUND_SEEDS, "reject_poses")


def test_estimator_default_range_and_bad_values() -> None:
    assert FewViewEigenspace().synth == AROUND_SEEDS
    seeds = torch.rand(1, 2, 1, 8, 8)
    with pytest.raises(
        ValueError, match=r"synth must be .*'around-seeds', 'circle', a Circle or None, got 'all'"
    ):
        FewViewEigenspace(2, synth="all").fit(seeds, [0.0, 10.0])
    with pytest.raises(
        ValueError, match=r"reject_poses must be \(start, stop, step\) in degrees or 'around-seeds', got None"
    ):
        FewViewEigenspace(2, reject_rate=0.05, reject_poses=None).fit(seeds, [0.0, 10.0])  # type: ignore[arg-type]


def test_reject_poses_default_lies_past_both_seeds() -> None:
    """The held-out views that calibrate rejection: 45 degrees past both end seeds, every
    2.5, the gallery's angles left out; as given otherwise; the circle's midpoints."""
    plan = seed_plan([0.0, 30.0], None, None, None)
    poses = reject_poses(plan, None)
    assert poses == (-45.0, 75.0, 2.5)
    held = held_out_thetas(plan, poses)
    assert min(held) == -45.0 and max(held) == 75.0
    assert sum(h < -20 for h in held) == sum(h > 50 for h in held) == 10  # both sides alike
    assert not set(held) & set(plan.thetas or [])
    assert reject_poses(plan, (-10.0, 10.0, 5.0)) == (-10.0, 10.0, 5.0)
    circle = seed_plan(None, 4, 0.0, (0.0, 0.0, 15.0))
    assert reject_poses(circle, None) == (7.5, 352.5, 15.0)
    assert held_out_thetas(circle, reject_poses(circle, None)) == [7.5 + 15.0 * i for i in range(24)]
    assert held_out_thetas(plan, None) == []


def test_off_gallery_compares_round_the_circle() -> None:
    # Seeds 0 and 170: the gallery runs to 190, which is -170.
    gallery = seed_plan([0.0, 170.0], None, None, None).thetas or []
    held = off_gallery((-180.0, 180.0, 2.5), gallery, "reject_poses")
    assert -170.0 not in held and -175.0 not in held and -180.0 not in held and 180.0 not in held
    assert -172.5 in held
    with pytest.raises(ValueError, match=r"--reject-poses \(0.0, 10.0, 5.0\) holds gallery angles only"):
        off_gallery((0.0, 10.0, 5.0), [0.0, 5.0, 370.0], "--reject-poses")


def test_estimator_held_out_views_around_each_objects_seeds(monkeypatch: pytest.MonkeyPatch) -> None:
    """The default reject_poses follow each object's own seeds (30 and 10 apart here)."""
    import torch_eigview.scale.galleries as estimator_module

    calls: list[list[float]] = []
    real = estimator_module.synthesize_views

    def spy(
        views: torch.Tensor, alpha: object, thetas: list[float], *args: object, **kwargs: object
    ) -> object:
        calls.append(list(thetas))
        return real(views, alpha, thetas, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(estimator_module, "synthesize_views", spy)
    seeds = [torch.rand(2, 1, 8, 8), torch.rand(2, 1, 8, 8)]
    FewViewEigenspace(2, reject_rate=0.2, options=SynthesisOptions(flow="ilk")).fit(
        seeds, [[0.0, 30.0], [0.0, 10.0]]
    )
    assert (min(calls[0]), max(calls[0])) == (-45.0, 75.0)
    assert (min(calls[1]), max(calls[1])) == (-45.0, 55.0)


def test_check_synth_names_the_argument_for_arrays() -> None:
    with pytest.raises(
        ValueError,
        match=r"synth must be \(start, stop, step\) in degrees, 'around-seeds', 'circle', a Circle or None",
    ):
        check_synth(np.array([-20.0, 20.0, 1.0]), around=True)
