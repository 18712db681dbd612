"""Maps built for the rows an object touches (``support``): the same views as the whole grid.

A seed row that is zero everywhere (a photograph's margin with its background set to 0)
gives zero synthesized rows wherever the maps reach only such rows, so the maps are built
for the band of target rows that can reach the object. The band's rows must equal the
whole-grid maps' rows bit for bit, and the views the whole-grid views.
"""

from __future__ import annotations

import pytest
import torch

import torch_eigview.warp.novel_view as novel_view
from torch_eigview.geometry.correspondence import correspondence_from_disparity
from torch_eigview.synthesis import SynthesisOptions, synthesize_views
from torch_eigview.warp.maps import WarpMaps
from torch_eigview.warp.novel_view import NovelViewWarp
from torch_eigview.warp.operator import SparseViewOperator

from tests.helpers import rand

H, W = 40, 24
THETAS = [-8.0, 0.0, 3.0, 10.0, 17.0]


def _object(rows: slice, seed: int = 0, channels: int = 2) -> torch.Tensor:
    """Two (1, C, H, W) seed views, zero outside ``rows``."""
    views = torch.zeros(2, 1, channels, H, W)
    views[..., rows, 3:-3] = rand(
        2, 1, channels, rows.stop - rows.start, W - 6, seed=seed, dtype=torch.float32
    )
    return views


def _correspondence(seed: int = 1) -> object:
    disparity = (rand(1, H, W, seed=seed, dtype=torch.float32) - 0.5) * 6
    corr = correspondence_from_disparity(disparity)
    valid = rand(1, H, W, seed=seed + 1) > 0.3
    return type(corr)(corr.disparity_12, corr.disparity_21, valid, valid.clone())


def _spy_maps(monkeypatch: pytest.MonkeyPatch, keep_support: bool) -> list[object]:
    """Records the ``support`` of every ``NovelViewWarp.maps`` call (passed on, or dropped:
    the whole-grid maps)."""
    seen: list[object] = []
    original = novel_view.NovelViewWarp.maps

    def spy(
        self: NovelViewWarp, corr: object, th: object, n_sources: int = 2, *, support: object = None
    ) -> WarpMaps:
        seen.append(support)
        return original(self, corr, th, n_sources, support=support if keep_support else None)  # type: ignore[arg-type]

    monkeypatch.setattr(novel_view.NovelViewWarp, "maps", spy)
    return seen


def _support(views: torch.Tensor) -> torch.Tensor:
    return (views != 0).any(dim=2).any(dim=-1).any(dim=0)  # (B, H)


@pytest.mark.parametrize("elevation", [0.0, 8.0, -25.0])
@pytest.mark.parametrize("n_sources", [1, 2])
def test_band_rows_and_views_equal_the_whole_grid(elevation: float, n_sources: int) -> None:
    views = _object(slice(14, 22))
    corr = _correspondence()
    warp = NovelViewWarp(10.0, elevation=elevation)
    whole = warp.maps(corr, THETAS, n_sources)
    band = warp.maps(corr, THETAS, n_sources, support=_support(views))
    rows = band.src_x.shape[-2]
    assert band.row0 > 0 and band.row0 + rows < H  # a real band: the test can fail
    if elevation == 0.0:  # rows stay rows: the object's rows and a tap's margin
        assert (band.row0, band.row0 + rows) == (14 - 2, 22 + 2)
    cut = slice(band.row0, band.row0 + rows)
    for name in ("src_x", "weight", "hit", "src_y"):
        a, b = getattr(whole, name), getattr(band, name)
        assert (a is None) == (b is None) == (elevation == 0.0 and name == "src_y"), name
        if a is not None:
            assert torch.equal(a[..., cut, :], b), name
    seeds = list(views[:n_sources])
    out = warp.apply_maps(band, seeds)
    assert out.shape == (1, len(THETAS), 2, H, W)
    assert torch.equal(out, warp.apply_maps(whole, seeds))
    masks = (views[:n_sources, :, 0] > 0.5).to(torch.float32)
    assert torch.equal(warp.apply_maps(band, seeds, masks), warp.apply_maps(whole, seeds, masks))


def test_rows_far_from_the_object_are_zero_in_the_whole_grid_too() -> None:
    # The premise of the band: with a tilt the rows outside it are zero in the whole-grid views.
    views = _object(slice(5, 9))
    corr = _correspondence()
    warp = NovelViewWarp(10.0, elevation=20.0)
    band = warp.maps(corr, THETAS, support=_support(views))
    out = warp.apply_maps(warp.maps(corr, THETAS), list(views))
    end = band.row0 + band.src_x.shape[-2]
    assert end < H  # the rows past the band: some there are
    assert out[..., : band.row0, :].abs().sum() == 0 and out[..., end:, :].abs().sum() == 0


def test_no_support_gives_zero_views() -> None:
    views = torch.zeros(2, 1, 1, H, W)
    warp = NovelViewWarp(10.0, elevation=5.0)
    band = warp.maps(_correspondence(), THETAS, support=_support(views))
    assert band.src_x.shape[-2] == 1
    assert torch.equal(warp.apply_maps(band, list(views)), torch.zeros(1, len(THETAS), 1, H, W))


@pytest.mark.parametrize(
    "options", [SynthesisOptions(flow="ilk"), SynthesisOptions(flow="ilk", silhouette=True)]
)
def test_synthesize_views_equals_the_whole_grid(
    monkeypatch: pytest.MonkeyPatch, options: SynthesisOptions
) -> None:
    seeds = _object(slice(10, 30), seed=3, channels=1)[:, 0]
    thetas = torch.arange(-10.0, 11.0, 5.0)
    original = novel_view.NovelViewWarp.maps
    built: list[WarpMaps] = []

    def keep(*args: object, **kwargs: object) -> WarpMaps:
        built.append(original(*args, **kwargs))  # type: ignore[arg-type]
        return built[-1]

    with monkeypatch.context() as patch:  # the banded run, its maps kept
        patch.setattr(novel_view.NovelViewWarp, "maps", keep)
        banded = synthesize_views(seeds, 10.0, thetas, options).views
    assert len(built) == 1 and built[0].src_x.shape[-2] < H  # a real band: the test can fail
    calls = _spy_maps(monkeypatch, keep_support=False)
    assert torch.equal(synthesize_views(seeds, 10.0, thetas, options).views, banded)
    assert len(calls) == 1 and isinstance(calls[0], torch.Tensor)


@pytest.mark.parametrize(
    ("support", "error", "match"),
    [
        (torch.ones(1, H), TypeError, r"support must be a bool tensor, got torch.float32"),
        ([True] * H, TypeError, r"support must be a bool tensor, got list"),
        (
            torch.ones(1, H - 1, dtype=torch.bool),
            ValueError,
            r"support must have shape \(B, H\) = \(1, 40\), got \(1, 39\)",
        ),
    ],
)
def test_bad_support(support: object, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        NovelViewWarp(10.0).maps(_correspondence(), THETAS, support=support)  # type: ignore[arg-type]


def test_band_maps_refused_where_every_row_is_needed() -> None:
    views = _object(slice(14, 22))
    warp = NovelViewWarp(10.0)
    band = warp.maps(_correspondence(), THETAS, support=_support(views))
    with pytest.raises(
        ValueError, match=r"maps must cover every row of the images \(40\), got rows 12\.\.23"
    ):
        SparseViewOperator.from_maps(views[:, 0], band)
    moved = WarpMaps(band.src_x, band.weight, band.hit, band.thetas, None, row0=H - 2)
    with pytest.raises(ValueError, match=r"maps hold rows 38\.\.49, which do not lie in the views' 40 rows"):
        warp.apply_maps(moved, list(views))


def test_seeds_taking_gradients_get_whole_grid_maps(monkeypatch: pytest.MonkeyPatch) -> None:
    # Zero rows outside a band are constants: the seeds' gradient there needs the whole grid.
    seeds = _object(slice(10, 30), seed=3, channels=1)[:, 0].requires_grad_()
    seen = _spy_maps(monkeypatch, keep_support=True)
    views = synthesize_views(seeds, 10.0, [2.0, 5.0], SynthesisOptions(flow="ilk")).views
    views.sum().backward()
    assert seen == [None] and seeds.grad is not None and seeds.grad[:, :, :5].abs().sum() > 0


def test_a_non_finite_disparity_gives_every_row() -> None:
    # No bound on the tilt's reach: the band is the whole grid, never a band that a NaN narrowed.
    views = _object(slice(14, 22))
    corr = _correspondence()
    corr.disparity_12[0, 3, 5] = float("nan")
    band = NovelViewWarp(10.0, elevation=8.0).maps(corr, THETAS, support=_support(views))
    assert band.row0 == 0 and band.src_x.shape[-2] == H


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA not available")
def test_no_band_off_the_cpu(monkeypatch: pytest.MonkeyPatch) -> None:
    # The band's bounds are host reads: on a GPU the maps cover every row.
    seeds = _object(slice(10, 30), seed=3, channels=1)[:, 0].cuda()
    seen = _spy_maps(monkeypatch, keep_support=True)
    synthesize_views(seeds, 10.0, [2.0, 5.0], SynthesisOptions(flow="tvl1"))
    assert seen == [None]
