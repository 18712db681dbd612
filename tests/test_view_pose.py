"""The pose of a view by geometry: ``view_angles`` on rendered turntable views (exact
angles known) and ``seed_pair_poses``' choice of seed pair, with its neighbour rule and
the circle's wrap."""

from __future__ import annotations

import math

import pytest
import torch

from torch_eigview.datasets import OrthographicCamera
from torch_eigview.datasets.renderer import render_views
from torch_eigview.datasets.shapes import make_object
from torch_eigview.synthesis import seed_pair_poses, view_angles
from torch_eigview.synthesis import view_pose as view_pose_module


@pytest.mark.parametrize("name", ["head", "egg"])
def test_rendered_views_between_the_seeds(name: str) -> None:
    """Rendered views 5°–25° into a 30° sector come back within a degree, by the default
    flow (measured: within 0.7° for these shapes)."""
    obj = make_object(name, seed=1)
    camera = OrthographicCamera(64)
    seeds = render_views(obj, [0.0, 30.0], camera)
    truth = [5.0, 15.0, 25.0]
    got = view_angles(render_views(obj, truth, camera), seeds, 30.0)
    assert got.shape == (3,) and got.dtype == torch.float64
    assert (got - torch.tensor(truth, dtype=torch.float64)).abs().max() < 1.0


def test_a_seed_mask_chooses_the_points() -> None:
    """``seed_mask`` replaces the brightness threshold: an empty mask leaves no point to
    fit (NaN), and a mask of another shape is named."""
    obj = make_object("egg", seed=1)
    camera = OrthographicCamera(32)
    seeds, views = render_views(obj, [0.0, 30.0], camera), render_views(obj, [15.0], camera)
    empty = torch.zeros(32, 32, dtype=torch.bool)
    assert math.isnan(float(view_angles(views, seeds, 30.0, seed_mask=empty)[0]))
    with pytest.raises(ValueError, match=r"seed_mask must be an \(32, 32\) bool tensor"):
        view_angles(views, seeds, 30.0, seed_mask=empty[:, :5])


def test_view_angles_weights_the_points_by_seed_1s_texture(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fit gets seed 1's column weight: where seed 1 does not vary along any row no
    point counts (NaN), and the weight is seed 1's, not the view's."""
    obj = make_object("egg", seed=1)
    camera = OrthographicCamera(32)
    seeds, views = render_views(obj, [0.0, 30.0], camera), render_views(obj, [15.0], camera)
    seen: list[torch.Tensor] = []
    real = view_pose_module._column_weight

    def spy(image: torch.Tensor) -> torch.Tensor:
        seen.append(image)
        return real(image)

    monkeypatch.setattr(view_pose_module, "_column_weight", spy)
    assert abs(float(view_angles(views, seeds, 30.0)[0]) - 15.0) < 1.0
    assert len(seen) == 1 and torch.equal(seen[0], seeds[0])
    monkeypatch.setattr(view_pose_module, "_column_weight", lambda image: torch.zeros(32 * 32))
    assert math.isnan(float(view_angles(views, seeds, 30.0)[0]))


def test_view_angles_checks_its_arguments() -> None:
    views = torch.rand(3, 1, 16, 16)
    with pytest.raises(ValueError, match=r"seeds must have shape \(2, 1, 16, 16\)"):
        view_angles(views, torch.rand(3, 1, 16, 16), 10.0)
    with pytest.raises(ValueError, match=r"views must have shape \(N, C, H, W\)"):
        view_angles(views[0], torch.rand(2, 1, 16, 16), 10.0)
    with pytest.raises(TypeError, match="views"):
        view_angles(views.long(), torch.rand(2, 1, 16, 16), 10.0)
    with pytest.raises(ValueError, match="alpha"):
        view_angles(views, torch.rand(2, 1, 16, 16), 0.0)
    assert view_angles(views[:0], torch.rand(2, 1, 16, 16), 10.0).shape == (0,)


class _Oracle:
    """Stands in for view_angles: each "view" is a 1×1 image holding its true pose, and the
    angle from a pair's first seed (whose image holds the seed's pose) is the difference,
    taken on the circle (the nearest turn). Records the pairs it was asked about."""

    def __init__(self) -> None:
        self.calls: list[tuple[float, int]] = []

    def __call__(
        self, views: torch.Tensor, seeds: torch.Tensor, alpha: float, options: object = None
    ) -> torch.Tensor:
        first = float(seeds[0, 0, 0, 0])
        self.calls.append((first, views.shape[0]))
        diff = views[:, 0, 0, 0].double() - first
        return torch.remainder(diff + 180.0, 360.0) - 180.0


def _as_images(poses: list[float]) -> torch.Tensor:
    return torch.tensor(poses, dtype=torch.float32).view(-1, 1, 1, 1)


def test_each_view_goes_to_the_pair_of_its_rough_pose(monkeypatch: pytest.MonkeyPatch) -> None:
    """Open seeds at 0, 10, 20: a rough pose chooses its sector and the measured angle is
    added to that pair's first seed; a rough pose before the first seed or past the last
    is kept (Eq. 2 would extrapolate)."""
    oracle = _Oracle()
    monkeypatch.setattr(view_pose_module, "view_angles", oracle)
    seed_poses = [0.0, 10.0, 20.0]
    truth = [3.0, 12.0, -8.0, 27.0, 19.0]
    rough = torch.tensor([4.0, 11.0, -6.0, 25.0, 20.0])
    got = seed_pair_poses(_as_images(truth), rough, _as_images(seed_poses), seed_poses)
    torch.testing.assert_close(got, torch.tensor([3.0, 12.0, -6.0, 25.0, 19.0], dtype=torch.float64))
    assert sorted(oracle.calls) == [(0.0, 1), (10.0, 2)]


def test_a_view_outside_its_pair_is_measured_with_the_neighbour(monkeypatch: pytest.MonkeyPatch) -> None:
    """A rough pose in the wrong sector: Eq. 2 puts the view past the pair's seed, the
    neighbouring pair on that side measures it, and its pose inside that sector is kept."""
    oracle = _Oracle()
    monkeypatch.setattr(view_pose_module, "view_angles", oracle)
    seed_poses = [0.0, 45.0, 90.0, 135.0]
    got = seed_pair_poses(_as_images([50.0]), torch.tensor([40.0]), _as_images(seed_poses), seed_poses)
    assert float(got[0]) == 50.0
    assert oracle.calls == [(0.0, 1), (45.0, 1)]


def test_no_pair_places_the_view(monkeypatch: pytest.MonkeyPatch) -> None:
    """Eq. 2 puts the view before the first of open seeds (no neighbour there), or past a
    pair whose neighbour does not place it either: the first measurement stands."""
    oracle = _Oracle()
    monkeypatch.setattr(view_pose_module, "view_angles", oracle)
    seed_poses = [0.0, 10.0, 20.0]
    got = seed_pair_poses(_as_images([-3.0]), torch.tensor([2.0]), _as_images(seed_poses), seed_poses)
    assert float(got[0]) == -3.0 and oracle.calls == [(0.0, 1)]
    got = seed_pair_poses(_as_images([45.0]), torch.tensor([5.0]), _as_images(seed_poses), seed_poses)
    assert float(got[0]) == 45.0 and oracle.calls[1:] == [(0.0, 1), (10.0, 1)]


def test_open_seeds_round_most_of_the_circle(monkeypatch: pytest.MonkeyPatch) -> None:
    """Open seeds spanning more than 180°: a rough pose given on another turn (here −115 for
    245) is taken on the turn nearest the seeds' middle, inside their span."""
    monkeypatch.setattr(view_pose_module, "view_angles", _Oracle())
    seed_poses = [0.0, 100.0, 200.0, 300.0]
    got = seed_pair_poses(_as_images([250.0]), torch.tensor([-115.0]), _as_images(seed_poses), seed_poses)
    assert float(got[0]) == 250.0


def test_the_circle_wraps(monkeypatch: pytest.MonkeyPatch) -> None:
    """Closed seeds round the circle: a rough pose past the last seed belongs to the pair
    that joins it to the first, and poses come back in [0, 360)."""
    oracle = _Oracle()
    monkeypatch.setattr(view_pose_module, "view_angles", oracle)
    seed_poses = [0.0, 90.0, 180.0, 270.0]
    truth = [300.0, 355.0, 10.0]
    rough = torch.tensor([290.0, -10.0, 370.0])
    got = seed_pair_poses(_as_images(truth), rough, _as_images(seed_poses), seed_poses, closed=True)
    torch.testing.assert_close(got, torch.tensor(truth, dtype=torch.float64))
    assert sorted(oracle.calls) == [(0.0, 1), (270.0, 2)]
    # Across the wrap: rough in pair 0, the view in pair 3 (and the other way round).
    oracle.calls.clear()
    got = seed_pair_poses(
        _as_images([350.0, 5.0]), torch.tensor([2.0, 355.0]), _as_images(seed_poses), seed_poses, closed=True
    )
    torch.testing.assert_close(got, torch.tensor([350.0, 5.0], dtype=torch.float64))
    assert sorted(oracle.calls) == [(0.0, 1), (0.0, 1), (270.0, 1), (270.0, 1)]


def test_a_view_the_fit_cannot_place_keeps_its_rough_pose(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(
        view_pose_module, "view_angles", lambda v, s, a, o=None: torch.full((v.shape[0],), math.nan)
    )
    got = seed_pair_poses(_as_images([5.0]), torch.tensor([7.5]), _as_images([0.0, 10.0]), [0.0, 10.0])
    assert float(got[0]) == 7.5


@pytest.mark.parametrize(
    ("seed_poses", "n_seeds", "closed", "match"),
    [
        ([0.0, 10.0, 10.0], 3, False, "must increase"),
        ([0.0, 200.0, 360.0], 3, False, "less than 360"),
        ([0.0, 10.0], 2, True, "at least 3"),
        ([0.0, 10.0, 20.0, 30.0], 3, False, "one pose per seed view"),
        ([0.0, math.nan], 2, False, "must be finite"),
    ],
)
def test_bad_seed_poses_are_named(seed_poses: list[float], n_seeds: int, closed: bool, match: str) -> None:
    seeds = _as_images([0.0] * n_seeds)
    with pytest.raises(ValueError, match=match):
        seed_pair_poses(_as_images([1.0]), torch.tensor([1.0]), seeds, seed_poses, closed=closed)


def test_seeds_must_match_the_views() -> None:
    with pytest.raises(ValueError, match=r"seeds must have shape \(V, 1, 1, 1\)"):
        seed_pair_poses(_as_images([1.0]), torch.tensor([1.0]), torch.zeros(2, 1, 2, 2), [0.0, 10.0])


def test_rough_poses_must_match_the_views() -> None:
    with pytest.raises(ValueError, match=r"rough must have shape \(2,\)"):
        seed_pair_poses(_as_images([1.0, 2.0]), torch.tensor([1.0]), _as_images([0.0, 10.0]), [0.0, 10.0])
    with pytest.raises(ValueError, match="rough"):
        seed_pair_poses(_as_images([1.0]), torch.tensor([math.nan]), _as_images([0.0, 10.0]), [0.0, 10.0])
    with pytest.raises(TypeError, match="rough"):
        seed_pair_poses(_as_images([1.0]), [1.0], _as_images([0.0, 10.0]), [0.0, 10.0])  # type: ignore[arg-type]


def test_column_weight_is_the_horizontal_derivative() -> None:
    """A pixel's weight: how much its row varies there (both channels' mean), 0 where flat
    and in the first and last column; a vertical edge weighs, a horizontal one does not."""
    image = torch.zeros(2, 4, 6)
    image[:, :, 3:] = 1.0  # a vertical edge between columns 2 and 3
    image[1, 2:, :] += 0.5  # a horizontal edge in channel 1 alone
    w = view_pose_module._column_weight(image).view(4, 6)
    torch.testing.assert_close(w[:, 2], torch.full((4,), 0.5))
    torch.testing.assert_close(w[:, 3], torch.full((4,), 0.5))
    assert (w[:, [0, 1, 4, 5]] == 0).all()
