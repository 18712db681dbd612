"""RandomTurntableRotation and per-object angles of NovelViewWarp: a batch of different
objects at different angles in one call equals the per-object calls.

The module invariants (check_module, with replayed parameters) are in tests/nn/test_modules.py.
"""

from __future__ import annotations

import pytest
import torch

from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.warp import NovelViewWarp, RandomTurntableRotation

from tests.helpers import rand

ALPHA = 12.0


def _objects(
    b: int, dtype: torch.dtype = torch.float64, device: torch.device | str = "cpu", h: int = 6, w: int = 9
) -> tuple[torch.Tensor, torch.Tensor, Correspondence]:
    """B different objects: random seed views and a random disparity each."""
    view1 = rand(b, 2, h, w, seed=30, dtype=dtype, device=device)
    view2 = rand(b, 2, h, w, seed=31, dtype=dtype, device=device)
    d12 = 3.0 * rand(b, h, w, seed=32) - 1.5
    return view1, view2, correspondence_from_disparity(d12.to(dtype)).to(device)


# --- NovelViewWarp with per-object angles -----------------------------------------------


@pytest.mark.parametrize("options", [{}, {"elevation": 25.0}, {"blend": "nearest"}, {"center": 3.0}])
@pytest.mark.parametrize("two_views", [True, False])
def test_per_object_angles_equal_the_per_object_calls(
    options: dict, two_views: bool, dtype: torch.dtype, tol: dict[str, float]
) -> None:
    view1, view2, corr = _objects(4, dtype)
    thetas = torch.tensor([[-10.0, 3.0], [5.0, 0.0], [ALPHA, 7.5], [-20.0, 30.0]])
    warp = NovelViewWarp(ALPHA, **options)
    second = view2 if two_views else None
    out = warp(view1, second, correspondence=corr, thetas=thetas)
    assert out.shape == (4, 2, 2, 6, 9) and out.dtype == dtype
    for i in range(4):
        one = warp(
            view1[i : i + 1],
            None if second is None else second[i : i + 1],
            correspondence=corr[i],
            thetas=thetas[i],
        )
        torch.testing.assert_close(out[i : i + 1], one, **tol)


def test_per_object_maps_are_the_per_object_maps_stacked() -> None:
    _, _, corr = _objects(3)
    thetas = torch.tensor([[4.0], [-9.0], [17.0]], dtype=torch.float64)
    maps = NovelViewWarp(ALPHA, elevation=10.0).maps(corr, thetas)
    assert maps.src_x.shape == (2, 3, 1, 6, 9)
    torch.testing.assert_close(maps.thetas, thetas)
    for i in range(3):
        one = NovelViewWarp(ALPHA, elevation=10.0).maps(corr[i], thetas[i])
        for field in ("src_x", "src_y", "weight", "hit"):
            torch.testing.assert_close(
                getattr(maps, field)[:, i : i + 1], getattr(one, field), equal_nan=True
            )


@pytest.mark.parametrize("elevation", [0.0, 10.0])
def test_objects_on_a_background_batched_equal_the_per_object_maps_bit_for_bit(elevation: float) -> None:
    """Objects trusted only inside their own box (a background around each, as rendered
    objects are): the batch, mostly background, builds its maps in the sparse regime while
    the large object 0 alone takes the dense one; the maps agree bit for bit."""
    b, h, w = 4, 10, 16
    d12 = 3.0 * rand(b, h, w, seed=40) - 1.5
    corr = correspondence_from_disparity(d12)
    box = torch.zeros(b, h, w, dtype=torch.bool)
    box[0] = True
    for i, (r, c) in enumerate([(1, 2), (4, 8), (2, 5)], start=1):
        box[i, r : r + 4, c : c + 5] = True
    corr.valid_12.logical_and_(box)  # in place: the record is frozen
    corr.valid_21.logical_and_(box)
    thetas = torch.tensor([[-14.0], [6.0], [ALPHA], [25.0]], dtype=torch.float64)
    warp = NovelViewWarp(ALPHA, elevation=elevation)
    maps = warp.maps(corr, thetas)
    assert float(maps.hit.double().mean()) < 0.5  # mostly holes: the batch's sparse regime
    for i in range(b):
        one = warp.maps(corr[i], thetas[i])
        for field in ("src_x", "src_y", "weight", "hit"):
            got, ref = getattr(maps, field), getattr(one, field)
            if ref is None:
                assert got is None
                continue
            assert torch.equal(got[:, i : i + 1], ref), field


def test_rendered_objects_one_call_equals_the_loop_over_samples_bit_for_bit() -> None:
    """The benchmark's case, small: different rendered objects on black with their exact
    correspondences, each turned by its own θ in one call, equal the per-sample warps."""
    from torch_eigview.datasets import SHAPES, OrthographicCamera, exact_correspondence, make_object, render

    camera, alpha = OrthographicCamera(20), 10.0
    objs = [make_object(shape) for shape in SHAPES[:4]]
    view1 = torch.stack([render(obj, 0.0, camera).image for obj in objs])
    view2 = torch.stack([render(obj, alpha, camera).image for obj in objs])
    corr = Correspondence.collate([exact_correspondence(obj, alpha, camera) for obj in objs])
    aug = RandomTurntableRotation(20.0, alpha, p=1.0, generator=torch.Generator().manual_seed(2))
    out = aug(view1, view2, correspondence=corr)
    assert float(corr.valid_12.float().mean()) < 0.6  # mostly background, as rendered
    for i, theta in enumerate(aug._params["degrees"].tolist()):
        one = aug.warp(view1[i : i + 1], view2[i : i + 1], correspondence=corr[i], thetas=[theta])
        assert torch.equal(out[i : i + 1], one[:, 0])


def test_affine_camera_per_object_angles() -> None:
    camera = torch.tensor([[2.0, 0.0, 0.0, 4.0], [0.0, -2.0, 0.0, 3.0]], dtype=torch.float64)
    view1, view2, corr = _objects(2)
    warp = NovelViewWarp(ALPHA, camera=camera)
    thetas = torch.tensor([[6.0], [-6.0]])
    out = warp(view1, view2, correspondence=corr, thetas=thetas)
    for i in range(2):
        one = warp(view1[i : i + 1], view2[i : i + 1], correspondence=corr[i], thetas=thetas[i])
        torch.testing.assert_close(out[i : i + 1], one)


@pytest.mark.parametrize(
    ("thetas", "match"),
    [
        (torch.zeros(3, 1), r"B = 2 rows \(one per object\)"),
        (torch.zeros(2, 0), r"T >= 1"),
        (torch.tensor([[10.0], [95.0]]), r"within \(-90, 90\)"),
        (torch.tensor([[10.0], [float("nan")]]), "finite"),
    ],
)
def test_per_object_angle_errors(thetas: torch.Tensor, match: str) -> None:
    view1, view2, corr = _objects(2)
    with pytest.raises(ValueError, match=match):
        NovelViewWarp(ALPHA)(view1, view2, correspondence=corr, thetas=thetas)


# --- RandomTurntableRotation ------------------------------------------------------------


@pytest.mark.parametrize("masks", [False, True])
def test_each_sample_is_its_own_warp_at_its_angle(
    masks: bool, dtype: torch.dtype, tol: dict[str, float]
) -> None:
    """Partial application: turned samples equal the per-sample warp, the others their view 1."""
    view1, view2, corr = _objects(5, dtype)
    seed_masks = (rand(2, 5, 6, 9, seed=33) > 0.3) if masks else None
    aug = RandomTurntableRotation((-20.0, 25.0), ALPHA, p=0.5)
    apply = torch.tensor([True, False, True, True, False])
    params = {"degrees": torch.tensor([-14.0, 3.0, 21.0, 0.5, 9.0], dtype=torch.float64), "batch_prob": apply}
    out = aug(view1, view2, correspondence=corr, params=params, masks=seed_masks)
    assert out.shape == view1.shape and out.dtype == dtype
    for i, theta in enumerate(params["degrees"].tolist()):
        if not apply[i]:
            assert torch.equal(out[i], view1[i])
            continue
        m = None if seed_masks is None else seed_masks[:, i : i + 1]
        one = aug.warp(view1[i : i + 1], view2[i : i + 1], correspondence=corr[i], thetas=[theta], masks=m)
        torch.testing.assert_close(out[i], one[0, 0], **tol)


def test_parameters_follow_p_and_the_range() -> None:
    torch.manual_seed(0)
    aug = RandomTurntableRotation((-5.0, 30.0), ALPHA, p=0.3)
    params = aug.forward_parameters((4000, 1, 8, 8))
    assert set(params) == {"degrees", "batch_prob"}
    assert params["degrees"].shape == params["batch_prob"].shape == (4000,)
    assert params["batch_prob"].dtype == torch.bool
    assert float(params["degrees"].min()) >= -5.0 and float(params["degrees"].max()) <= 30.0
    # 4000 Bernoulli(0.3) draws: the standard deviation of the fraction is 0.007.
    assert abs(float(params["batch_prob"].double().mean()) - 0.3) < 0.03
    assert abs(float(params["degrees"].mean()) - 12.5) < 1.0  # uniform: sd of the mean 0.16
    assert RandomTurntableRotation(10.0, ALPHA, p=1.0).forward_parameters((3,))["batch_prob"].all()
    assert not RandomTurntableRotation(10.0, ALPHA, p=0.0).forward_parameters((3,))["batch_prob"].any()


def test_same_on_batch_draws_once() -> None:
    aug = RandomTurntableRotation(20.0, ALPHA, p=0.5, same_on_batch=True)
    for seed in range(6):
        torch.manual_seed(seed)
        params = aug.forward_parameters((7, 1, 4, 4))
        assert (params["degrees"] == params["degrees"][0]).all()
        assert (params["batch_prob"] == params["batch_prob"][0]).all()
    torch.manual_seed(0)
    per_sample = RandomTurntableRotation(20.0, ALPHA).forward_parameters((7,))["degrees"]
    assert len(set(per_sample.tolist())) == 7


def test_reproducible_under_manual_seed_and_generator() -> None:
    view1, view2, corr = _objects(6)
    aug = RandomTurntableRotation(20.0, ALPHA, p=0.5)
    torch.manual_seed(3)
    first = aug(view1, view2, correspondence=corr)
    params = aug._params
    torch.manual_seed(3)
    assert torch.equal(aug(view1, view2, correspondence=corr), first)
    assert torch.equal(aug(view1, view2, correspondence=corr, params=params), first)
    draws = [
        RandomTurntableRotation(20.0, ALPHA, generator=torch.Generator().manual_seed(7)).forward_parameters(
            (6,)
        )
        for _ in range(2)
    ]
    assert all(torch.equal(draws[0][k], draws[1][k]) for k in draws[0])
    other = RandomTurntableRotation(20.0, ALPHA, generator=torch.Generator().manual_seed(8))
    assert not torch.equal(other.forward_parameters((6,))["degrees"], draws[0]["degrees"])


def test_replayed_params_are_kept_and_float_flags_accepted() -> None:
    view1, view2, corr = _objects(3)
    aug = RandomTurntableRotation(20.0, ALPHA)
    degrees = torch.tensor([4.0, -7.0, 11.0], dtype=torch.float64)
    out = aug(
        view1,
        view2,
        correspondence=corr,
        params={"degrees": degrees, "batch_prob": torch.tensor([1.0, 0.0, 1.0])},
    )
    assert torch.equal(aug._params["batch_prob"], torch.tensor([True, False, True]))
    assert torch.equal(out[1], view1[1])
    everywhere = aug(view1, view2, correspondence=corr, params={"degrees": degrees})  # batch_prob: all
    assert aug._params["batch_prob"].all()
    torch.testing.assert_close(everywhere[[0, 2]], out[[0, 2]])
    nowhere = aug(
        view1, view2, correspondence=corr, params={"degrees": degrees, "batch_prob": torch.zeros(3)}
    )
    assert torch.equal(nowhere, view1) and nowhere.data_ptr() != view1.data_ptr()


def test_gradients_reach_the_seed_views_of_turned_samples() -> None:
    view1, view2, corr = _objects(3)
    v1, v2 = view1.clone().requires_grad_(True), view2.clone().requires_grad_(True)
    aug = RandomTurntableRotation(20.0, ALPHA)
    params = {"degrees": torch.tensor([5.0, 6.0, 7.0]), "batch_prob": torch.tensor([True, False, True])}
    aug(v1, v2, correspondence=corr, params=params).sum().backward()
    assert v1.grad is not None and v2.grad is not None
    assert v2.grad[[0, 2]].abs().sum() > 0 and v2.grad[1].abs().sum() == 0
    torch.testing.assert_close(v1.grad[1], torch.ones_like(v1[1]))  # passed through unchanged


def test_repr() -> None:
    text = repr(RandomTurntableRotation((-3.0, 8.0), ALPHA, p=0.25, same_on_batch=True))
    assert "degrees=(-3.0, 8.0), p=0.25, same_on_batch=True" in text and "NovelViewWarp(alpha=12.0" in text


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (dict(degrees=-5.0), ValueError, r"degrees=-5.0 must be a finite number >= 0"),
        (dict(degrees=(10.0, 5.0)), ValueError, r"-90 < lo <= hi < 90"),
        (dict(degrees=(-95.0, 5.0)), ValueError, r"-90 < lo <= hi < 90"),
        (dict(degrees=(1.0, 2.0, 3.0)), ValueError, "a pair"),
        (dict(degrees="20"), TypeError, "degrees"),
        (dict(p=1.5), ValueError, r"p=1.5 must be a probability"),
        (dict(same_on_batch=1), TypeError, "same_on_batch must be a bool"),
        (dict(generator=0), TypeError, "generator must be a torch.Generator"),
        (dict(blend="cubic"), ValueError, "blend must be one of"),
    ],
)
def test_constructor_errors(kwargs: dict, error: type[Exception], match: str) -> None:
    args = dict(degrees=20.0, alpha=ALPHA) | kwargs
    with pytest.raises(error, match=match):
        RandomTurntableRotation(**args)


def test_forward_errors() -> None:
    view1, view2, corr = _objects(2)
    aug = RandomTurntableRotation(20.0, ALPHA)
    with pytest.raises(ValueError, match=r"view1 must .*\(B, C, H, W\)"):
        aug(view1[0], view2[0], correspondence=corr)
    with pytest.raises(ValueError, match=r"'degrees' and optionally 'batch_prob', got \['angle'\]"):
        aug(view1, view2, correspondence=corr, params={"angle": torch.zeros(2)})
    with pytest.raises(ValueError, match=r"params\['degrees'\] must have shape \(B,\) = \(2,\), got \(3,\)"):
        aug(view1, view2, correspondence=corr, params={"degrees": torch.zeros(3)})
    with pytest.raises(ValueError, match=r"params\['batch_prob'\] must have shape"):
        aug(
            view1, view2, correspondence=corr, params={"degrees": torch.zeros(2), "batch_prob": torch.ones(1)}
        )
    with pytest.raises(TypeError, match="params must be a dict"):
        aug(view1, view2, correspondence=corr, params=[torch.zeros(2)])
    with pytest.raises(ValueError, match="correspondence must have shape"):
        aug(view1, view2, correspondence=corr[:1], params={"degrees": torch.zeros(2)})
