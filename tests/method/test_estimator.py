"""Tests for ``FewViewEigenspace``: the whole method from seed views, against the COIL
experiment (bit for bit), on rendered objects, and fitted from streamed blocks."""

from __future__ import annotations

import pytest
import torch
from torch.utils.data import DataLoader, TensorDataset

from torch_eigview.datasets import OrthographicCamera, make_object, render_views
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.errors import NotFittedError
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.method import ALL_COMPONENTS, AROUND_SEEDS, FewViewEigenspace, resolve_components
from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.synthesis import SynthesisOptions

from tests.helpers import rand

SHAPES = ("ellipsoid", "egg", "head")
CAMERA = OrthographicCamera(32)


def _render(angles: list[float]) -> torch.Tensor:
    """(O, T, 1, 32, 32) views of the three objects at ``angles``."""
    return torch.stack([render_views(make_object(name), angles, CAMERA) for name in SHAPES])


@pytest.fixture(scope="module")
def seeds() -> torch.Tensor:
    return _render([0.0, 10.0])


@pytest.fixture(scope="module")
def fitted(seeds: torch.Tensor) -> FewViewEigenspace:
    return FewViewEigenspace(8).fit(seeds, [0.0, 10.0], labels=[3, 5, 9])


# ---------------------------------------------------------------------- COIL: the experiment's recognizer


@pytest.mark.coil
@pytest.mark.parametrize(
    ("synth", "coil_synth"),
    [((-20.0, 20.0, 1.0), (-20.0, 20.0, 1.0)), (AROUND_SEEDS, (-20.0, 30.0, 1.0))],
    ids=["paper-range", "around-seeds"],
)
def test_equals_the_coil_experiment(
    folder: CoilFolder, synth: tuple[float, float, float] | str, coil_synth: tuple[float, float, float]
) -> None:
    """Objects 1-3 with seeds at 0 and 10 degrees: the same gallery, layer and answers, bit
    for bit, with the paper's range and with the default, 20° past both seeds (−20..30)."""
    objects = [1, 2, 3]
    reference = CoilExperiment(alpha=10.0, objects=objects, synth=coil_synth).run(folder).recognizer
    seeds = torch.stack([folder.images(o, [0.0, 10.0]) for o in objects])
    est = FewViewEigenspace(15, synth=synth).fit(seeds, [0.0, 10.0], labels=objects)
    for name in ("codes", "labels", "poses"):
        assert torch.equal(getattr(est.recognizer_, name), getattr(reference, name)), name
    assert torch.equal(est.projection_.components, reference.projection.components)
    angles = [-45.0 + 5.0 * i for i in range(19)]
    for obj in objects:
        views = folder.images(obj, angles)
        got, want = est.predict(views), reference.predict(views)
        assert torch.equal(got.labels, want.labels)
        assert torch.equal(got.distances, want.distances)
        assert torch.equal(got.poses, want.poses)


# ---------------------------------------------------------------------- fit from seed views


def test_gallery_of_synthesized_views(fitted: FewViewEigenspace, seeds: torch.Tensor) -> None:
    # The default range: every degree from 20 before the first seed (0) to 20 past the last (10).
    assert fitted.gallery_labels_.tolist() == [3] * 51 + [5] * 51 + [9] * 51
    torch.testing.assert_close(fitted.gallery_poses_[:51], torch.arange(-20.0, 31.0))
    assert len(fitted.elevations_) == 3 and all(len(e) == 1 for e in fitted.elevations_)
    assert fitted.image_shape_ == (1, 32, 32)
    assert isinstance(fitted.eigenspace_, Eigenspace) and fitted.eigenspace_.n_components_ == 8
    assert fitted.projection_.unit_norm
    result = fitted.predict(seeds.flatten(0, 1))
    assert result.labels.tolist() == [3, 3, 5, 5, 9, 9]
    assert fitted.transform(seeds[0]).shape == (2, 8)


def test_recognizes_unseen_views(fitted: FewViewEigenspace) -> None:
    tests = _render([-10.0, 5.0, 20.0])
    assert fitted.predict(tests.flatten(0, 1)).labels.tolist() == [3] * 3 + [5] * 3 + [9] * 3


def test_absolute_angles_offset_the_poses(seeds: torch.Tensor) -> None:
    """The gallery's poses are the first seed's angle plus the synthesized offsets, wrapped."""
    a = FewViewEigenspace(2, synth=(-5.0, 5.0, 5.0)).fit(seeds[:1], [0.0, 10.0])
    b = FewViewEigenspace(2, synth=(-5.0, 5.0, 5.0)).fit(seeds[:1], [175.0, 185.0])
    assert a.gallery_poses_.tolist() == [-5.0, 0.0, 5.0]
    assert b.gallery_poses_.tolist() == [170.0, 175.0, 180.0]
    assert torch.equal(a.recognizer_.codes, b.recognizer_.codes)


def test_three_seeds_extend_the_range() -> None:
    seeds = _render([0.0, 10.0, 20.0])[:2]
    est = FewViewEigenspace(4, synth=(-20.0, 20.0, 2.0)).fit(seeds, [0.0, 10.0, 20.0])
    assert est.gallery_poses_[:26].tolist() == [-20.0 + 2 * i for i in range(26)]  # to 20 + 10
    assert all(len(e) == 2 for e in est.elevations_)
    fixed = FewViewEigenspace(4, synth=(-20.0, 20.0, 2.0), synth_follows_seeds=False)
    assert fixed.fit(seeds, [0.0, 10.0, 20.0]).gallery_labels_.numel() == 2 * 21


def test_per_object_angles_and_unequal_steps(seeds: torch.Tensor) -> None:
    three = _render([0.0, 10.0, 25.0])[0]
    est = FewViewEigenspace(4, synth=(0.0, 10.0, 5.0)).fit(
        [seeds[0], three], [[0.0, 10.0], [0.0, 10.0, 25.0]]
    )
    assert est.gallery_poses_.tolist() == [0.0, 5.0, 10.0, *[5.0 * i for i in range(6)]]


def test_sparse_fits_the_seeds_alone(seeds: torch.Tensor) -> None:
    est = FewViewEigenspace(None, synth=None).fit(seeds, [0.0, 10.0])
    assert est.gallery_labels_.tolist() == [0, 0, 1, 1, 2, 2]
    assert est.gallery_poses_.tolist() == [0.0, 10.0] * 3
    assert est.elevations_ == []
    assert est.eigenspace_.n_components_ == 5  # every component: rank of 6 centred views


def test_options_reach_the_synthesis(seeds: torch.Tensor) -> None:
    plain = FewViewEigenspace(1, synth=(0.0, 5.0, 5.0), options=SynthesisOptions(elevation=0.0))
    assert plain.fit(seeds[:1], [0.0, 10.0]).elevations_ == [[0.0]]


def test_kernel_and_to_module(fitted: FewViewEigenspace, seeds: torch.Tensor) -> None:
    est = FewViewEigenspace(6, synth=(-10.0, 10.0, 5.0), kernel="rbf", gamma="median").fit(seeds, [0.0, 10.0])
    assert isinstance(est.eigenspace_, KernelEigenspace)
    assert isinstance(est.to_module(), KernelProjection)
    assert est.predict(seeds.flatten(0, 1)).labels.tolist() == [0, 0, 1, 1, 2, 2]
    layer = fitted.to_module()
    raw = fitted.to_module(unit_norm=False)
    assert isinstance(layer, EigenProjection) and layer.unit_norm and not raw.unit_norm
    views = seeds[1]
    torch.testing.assert_close(layer(views), raw(unit_rows(views)))
    torch.testing.assert_close(layer(views), fitted.transform(views))


def test_not_fitted() -> None:
    est = FewViewEigenspace()
    for call in (
        lambda: est.predict(torch.zeros(1, 4)),
        est.to_module,
        lambda: est.transform(torch.zeros(1, 4)),
    ):
        with pytest.raises(NotFittedError, match="not fitted"):
            call()


@pytest.mark.parametrize(
    ("params", "error", "match"),
    [
        (dict(synth=(0.0, 1.0)), ValueError, "synth must be"),
        (dict(synth=(0.0, 1.0, 0.0)), ValueError, "synth step must be positive"),
        (dict(synth=(1.0, 0.0, 1.0)), ValueError, "start <= stop"),
        (dict(gamma=0.5), ValueError, "needs a kernel"),
        (dict(kernel="sigmoid"), ValueError, "kernel="),
        (dict(n_components=0), ValueError, "n_components=0"),
        (dict(unit_norm=1), TypeError, "unit_norm must be a bool"),
        (dict(options="tvl1"), TypeError, "options must be"),
        (dict(max_views=0), ValueError, "max_views=0"),
    ],
)
def test_hyperparameters_are_checked_by_fit(
    params: dict[str, object], error: type[Exception], match: str, seeds: torch.Tensor
) -> None:
    est = FewViewEigenspace(**params)  # type: ignore[arg-type]
    assert all(getattr(est, k) == v for k, v in params.items())  # stored as given
    with pytest.raises(error, match=match):
        est.fit(seeds, [0.0, 10.0])


@pytest.mark.parametrize(
    ("seeds", "angles", "labels", "error", "match"),
    [
        (rand(2, 2, 1, 8, 8)[0], [0.0, 10.0], None, ValueError, r"\(O, V, C, H, W\)"),
        ("seeds", [0.0, 10.0], None, TypeError, "seeds must be"),
        ([], [0.0, 10.0], None, ValueError, "at least one object"),
        ([rand(2, 1, 8, 8), rand(2, 1, 8, 9)], [0.0, 10.0], None, ValueError, r"seeds\[1\]"),
        (rand(2, 2, 1, 8, 8), [0.0], None, ValueError, "one angle per seed view"),
        (rand(2, 2, 1, 8, 8), [[0.0, 10.0]], None, ValueError, "one list of angles per object"),
        (rand(2, 2, 1, 8, 8), [0.0, float("nan")], None, ValueError, "finite"),
        (rand(2, 2, 1, 8, 8), [0.0, 10.0], [1], ValueError, "one int or name per object"),
        (rand(2, 1, 1, 8, 8), [0.0], None, ValueError, "V >= 2"),
        (rand(2, 2, 1, 8, 8), [0.0, 180.0], None, ValueError, "180"),
    ],
)
def test_inputs_are_checked(
    seeds: object, angles: object, labels: object, error: type[Exception], match: str
) -> None:
    with pytest.raises(error, match=match):
        FewViewEigenspace(1).fit(seeds, angles, labels)


def test_resolve_components() -> None:
    assert resolve_components(None) == ALL_COMPONENTS < 1.0
    assert resolve_components(3) == 3
    with pytest.raises(TypeError, match="n_components"):
        resolve_components("all")


# ---------------------------------------------------------------------- fit from streamed blocks


@pytest.fixture(scope="module")
def gallery() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Real views of the three objects every 5 degrees: (39, 1, 32, 32), labels, poses."""
    angles = [-30.0 + 5.0 * i for i in range(13)]
    views = _render(angles)
    labels = torch.arange(3).repeat_interleave(13)
    return views.flatten(0, 1).double(), labels, torch.tensor(angles * 3, dtype=torch.float64)


def test_fit_blocks_equals_fit(gallery: tuple[torch.Tensor, torch.Tensor, torch.Tensor]) -> None:
    views, labels, poses = gallery
    whole = FewViewEigenspace(6, synth=None).fit(views.reshape(3, 13, 1, 32, 32), [poses[:13].tolist()] * 3)
    loader = DataLoader(TensorDataset(views, labels, poses), batch_size=10)
    streamed = FewViewEigenspace(6, max_views=16).fit_blocks(loader)
    assert torch.equal(streamed.gallery_labels_, whole.gallery_labels_)
    assert torch.equal(streamed.gallery_poses_, whole.gallery_poses_)
    torch.testing.assert_close(streamed.recognizer_.codes, whole.recognizer_.codes, atol=1e-10, rtol=1e-10)
    assert streamed.image_shape_ == (1, 32, 32) and streamed.elevations_ == []
    assert torch.equal(streamed.predict(views).labels, labels)


def test_fit_blocks_sources(gallery: tuple[torch.Tensor, torch.Tensor, torch.Tensor]) -> None:
    """A list, a callable and a one-shot generator of bare tensors: one object per block."""
    views = gallery[0]
    blocks = list(views.split(13))
    expected = torch.arange(3).repeat_interleave(13)
    for source in (blocks, lambda: iter(blocks), (b for b in blocks)):
        est = FewViewEigenspace(4, unit_norm=False).fit_blocks(source)
        assert torch.equal(est.gallery_labels_, expected)
        assert not bool(est.gallery_poses_.any())


def test_fit_blocks_rejects(gallery: tuple[torch.Tensor, torch.Tensor, torch.Tensor]) -> None:
    views = gallery[0]
    with pytest.raises(ValueError, match="shuffle"):
        FewViewEigenspace(4).fit_blocks(DataLoader(TensorDataset(views), batch_size=8, shuffle=True))
    with pytest.raises(ValueError, match="kernel must be None"):
        FewViewEigenspace(4, kernel="rbf").fit_blocks([views])
    with pytest.raises(TypeError, match="wrap it in a list"):
        FewViewEigenspace(4).fit_blocks(views)
    with pytest.raises(ValueError, match=r"blocks\[0\] labels"):
        FewViewEigenspace(4).fit_blocks([(views, torch.zeros(len(views)))])
    with pytest.raises(ValueError, match=r"blocks\[0\] views must have shape"):
        FewViewEigenspace(4).fit_blocks([views.flatten(1)])


def test_masks_go_to_synthesis(seeds: torch.Tensor) -> None:
    """Seed masks replace the brightness threshold: the gallery is synthesize_views(masks=)'s."""
    from torch_eigview.synthesis import synthesize_views

    masks = seeds[:, :, 0] > 0.3  # (O, V, H, W): a mask that the threshold would not give
    options = SynthesisOptions(silhouette=True, elevation=0.0)
    est = FewViewEigenspace(8, synth=(-10.0, 10.0, 5.0), options=options).fit(seeds, [0.0, 10.0], masks=masks)
    want = synthesize_views(seeds[1], 10.0, [-10.0, -5.0, 0.0, 5.0, 10.0], options, masks=masks[1])
    plain = FewViewEigenspace(8, synth=(-10.0, 10.0, 5.0), options=options).fit(seeds, [0.0, 10.0])
    codes = est.transform(want.views)
    assert torch.allclose(codes, est.recognizer_.codes[5:10], atol=1e-5)
    assert not torch.allclose(plain.recognizer_.codes, est.recognizer_.codes, atol=1e-3)
    per_object = [masks[0], None, masks[2]]  # a sequence, one entry without
    FewViewEigenspace(8, synth=(-10.0, 10.0, 5.0), options=options).fit(seeds, [0.0, 10.0], masks=per_object)
    with pytest.raises(
        ValueError, match=r"masks\[1\] \(of seeds\[1\]\): masks must have shape \(V, H, W\) = \(2, 32, 32\)"
    ):
        FewViewEigenspace(8).fit(seeds, [0.0, 10.0], masks=[masks[0], masks[1, :, :16], None])
    empty = masks.clone()
    empty[2, 1] = False
    with pytest.raises(ValueError, match=r"masks\[2\]\[1\] is all background"):
        FewViewEigenspace(8).fit(seeds, [0.0, 10.0], masks=empty)
    with pytest.raises(TypeError, match=r"masks\[0\] \(of seeds\[0\]\): masks must be None or a bool tensor"):
        FewViewEigenspace(8).fit(seeds, [0.0, 10.0], masks=[masks[0].float(), None, None])
    with pytest.raises(ValueError, match=r"masks must hold one entry per object \(3\), got 2"):
        FewViewEigenspace(8).fit(seeds, [0.0, 10.0], masks=[None, None])


def test_angles_past_a_quarter_turn_from_their_seed_are_refused_by_name(seeds: torch.Tensor) -> None:
    """Before any synthesis: the gallery or the held-out views a pair would make from 90
    degrees or more past its first seed, named with the seeds and how far they reach."""
    with pytest.raises(ValueError, match=r"synth asks for views 105 degrees .* seeds at 0, 10 degrees"):
        FewViewEigenspace(3, synth=(-20.0, 105.0, 5.0), synth_follows_seeds=False).fit(seeds, [0.0, 10.0])
    with pytest.raises(ValueError, match=r"reject_poses asks for views 100 degrees"):
        FewViewEigenspace(3, reject_rate=0.1, reject_poses=(-100.0, 20.0, 5.0)).fit(seeds, [0.0, 10.0])


def test_fit_blocks_takes_view_dataset_items(
    gallery: tuple[torch.Tensor, torch.Tensor, torch.Tensor], tmp_path: object
) -> None:
    """A ViewDataset, and a DataLoader over it (default collate), feed fit_blocks as they are:
    the same model as the (views, labels, poses) blocks, with the object names as label_names_."""
    from pathlib import Path

    from PIL import Image

    from torch_eigview.datasets import ViewDataset, ViewManifest

    views, labels, poses = gallery
    root = Path(str(tmp_path))
    for view, label, pose in zip(views, labels.tolist(), poses.tolist(), strict=True):
        pixels = (view[0] * 255).round().clamp(0, 255).to(torch.uint8).numpy()
        Image.fromarray(pixels).save(root / f"{'abc'[label]}_{int(pose) % 360}.png")
    dataset = ViewDataset(ViewManifest.from_pattern(root, "{object}_{azimuth}.png"), channels=1)
    read = torch.stack([item["image"] for item in dataset])
    read_labels = torch.tensor([ord(item["object"]) - ord("a") for item in dataset])
    read_poses = torch.tensor([item["azimuth"] for item in dataset], dtype=torch.float64)
    expected = FewViewEigenspace(4, max_views=16).fit_blocks([(read, read_labels, read_poses)])
    for blocks in (dataset, DataLoader(dataset, batch_size=7)):
        est = FewViewEigenspace(4, max_views=16).fit_blocks(blocks)
        assert est.label_names_ == ["a", "b", "c"]  # the manifest lists the objects so
        assert torch.equal(est.gallery_labels_, expected.gallery_labels_)
        torch.testing.assert_close(est.gallery_poses_, expected.gallery_poses_)
        torch.testing.assert_close(est.recognizer_.codes, expected.recognizer_.codes, atol=1e-5, rtol=1e-5)
    with pytest.raises(ValueError, match=r"blocks\[0\] is a dict without the key 'image'"):
        FewViewEigenspace(4).fit_blocks([{"views": read}])
    with pytest.raises(ValueError, match="mixes ViewDataset items"):
        FewViewEigenspace(4).fit_blocks([dataset[0], (read[:5], read_labels[:5])])


def test_to_module_unit_norm_is_as_fitted() -> None:
    """One rule for every ``to_module``: the layer does to its input what the fit did to the
    views (FewViewEigenspace: its unit_norm; Eigenspace and KernelEigenspace fit the rows as
    given, so False); an explicit unit_norm overrides it either way."""
    seeds = rand(2, 4, 1, 8, 8, seed=3)
    for unit in (True, False):
        est = FewViewEigenspace(3, synth=None, unit_norm=unit).fit(seeds, [0.0, 10.0, 20.0, 30.0])
        assert est.to_module().unit_norm is unit and est.recognizer_.projection.unit_norm is unit
        assert est.to_module(unit_norm=not unit).unit_norm is (not unit)
    rows = seeds.flatten(0, 1)
    for space in (Eigenspace(3).fit(rows), KernelEigenspace(3, kernel="rbf").fit(rows)):
        assert space.to_module().unit_norm is False
        assert space.to_module(unit_norm=True).unit_norm is True
