"""Correspondences: exact disparities and their inverse, and the optical-flow estimate."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
from scipy import ndimage

from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.geometry.flow import estimate_correspondence

H, W = 48, 64


def _texture(seed: int, sigma: float = 2.0, shape: tuple[int, int] = (H, W)) -> np.ndarray:
    """Smooth random texture in [0, 1]: Gaussian-filtered white noise (seeded, CPU)."""
    gen = torch.Generator().manual_seed(seed)
    noise = torch.randn(shape, generator=gen, dtype=torch.float64).numpy()
    tex = ndimage.gaussian_filter(noise, sigma)
    return (tex - tex.min()) / (tex.max() - tex.min())


def _shifted(tex: np.ndarray, shift: float) -> np.ndarray:
    """The texture moved right by ``shift`` pixels: view2(x) = view1(x - shift), x2 = x1 + shift."""
    return ndimage.shift(tex, (0.0, shift), order=3, mode="nearest")


def _smooth_disparity(b: int, h: int, w: int, seed: int) -> torch.Tensor:
    """(B, H, W) smooth disparity with |d/dx| < 0.6: x2 = x + d(x) is increasing along rows."""
    gen = torch.Generator().manual_seed(seed)
    amp, phase, offset = torch.rand(3, b, 1, 1, generator=gen, dtype=torch.float64)
    x = torch.arange(w, dtype=torch.float64)
    y = torch.arange(h, dtype=torch.float64)[:, None]
    bump = torch.sin(2 * math.pi * x / w + 6 * phase + 0.3 * y)
    return (1 + 2 * amp) * bump + 4 * (offset - 0.5)


def _inside(x: torch.Tensor, w: int) -> torch.Tensor:
    return (x >= 0) & (x <= w - 1)


# --- correspondence_from_disparity ------------------------------------------------------


@pytest.mark.parametrize("shift", [2.5, -1.25, 0.0])
def test_constant_disparity(shift: float, dtype: torch.dtype) -> None:
    h, w = 5, 10
    corr = correspondence_from_disparity(torch.full((h, w), shift, dtype=dtype))
    assert corr.shape == (1, h, w)
    assert corr.disparity_12.dtype == corr.disparity_21.dtype == dtype
    assert corr.valid_12.dtype == corr.valid_21.dtype == torch.bool
    assert corr.vertical_12 is None
    torch.testing.assert_close(corr.disparity_21, torch.full((1, h, w), -shift, dtype=dtype))
    cols = torch.arange(w, dtype=dtype).expand(1, h, w)
    # Valid exactly where the match stays inside the image.
    assert torch.equal(corr.valid_12, _inside(cols + shift, w))
    assert torch.equal(corr.valid_21, _inside(cols - shift, w))


def test_smooth_disparity_inverse_round_trips(dtype: torch.dtype, tol: dict[str, float]) -> None:
    b, h, w = 3, 7, 40
    d12 = _smooth_disparity(b, h, w, seed=0)
    corr = correspondence_from_disparity(d12.to(dtype))
    d21 = corr.disparity_21.double()
    cols = torch.arange(w, dtype=torch.float64)
    x2_of_x1 = cols + d12
    # Reference inverse: numpy's interpolation of the (increasing) forward map, per row.
    covered = (cols >= x2_of_x1[..., :1]) & (cols <= x2_of_x1[..., -1:])
    x1_ref = torch.stack(
        [
            torch.stack([torch.from_numpy(np.interp(cols, x2_of_x1[i, j], cols)) for j in range(h)])
            for i in range(b)
        ]
    )
    torch.testing.assert_close((cols + d21)[covered], x1_ref[covered], **tol)
    # x2 -> x1 -> x2 again, with the forward map interpolated linearly between pixels.
    x1 = (cols + d21).clamp(0, w - 1)
    back = torch.stack(
        [
            torch.stack([torch.from_numpy(np.interp(x1[i, j], cols, x2_of_x1[i, j])) for j in range(h)])
            for i in range(b)
        ]
    )
    torch.testing.assert_close(back[covered], cols.expand(b, h, w)[covered], **tol)
    # Masks: every view-1 pixel whose match is inside is valid; every view-2 pixel that view 1
    # sees is valid; a view-2 pixel whose match leaves the image is not.
    assert torch.equal(corr.valid_12, _inside(x2_of_x1, w))
    assert bool(corr.valid_21[covered].all())
    assert not bool((corr.valid_21 & ~_inside(cols + d21, w)).any())
    assert bool((~corr.valid_21).any()) and bool((~corr.valid_12).any())  # the test bites


def test_threshold_and_explicit_reverse_map() -> None:
    d12 = torch.ones(4, 9, dtype=torch.float64)
    d21 = torch.full((4, 9), -1.0 + 0.6, dtype=torch.float64)  # round trip off by 0.6 px
    loose = correspondence_from_disparity(d12, d21, threshold=1.0)
    strict = correspondence_from_disparity(d12, d21, threshold=0.5)
    assert torch.equal(loose.disparity_21, d21[None])
    assert bool(loose.valid_12[..., :-1].all()) and not bool(loose.valid_12[..., -1].any())
    assert not bool(strict.valid_12.any()) and not bool(strict.valid_21.any())


def test_explicit_masks_are_kept() -> None:
    d12 = torch.zeros(2, 3, 4)
    v12 = torch.rand(2, 3, 4, generator=torch.Generator().manual_seed(0)) < 0.5
    corr = correspondence_from_disparity(d12, -d12, valid_12=v12, valid_21=~v12)
    assert torch.equal(corr.valid_12, v12) and torch.equal(corr.valid_21, ~v12)


def test_to_moves_and_casts(device: torch.device) -> None:
    corr = correspondence_from_disparity(torch.full((2, 3, 4), 0.5, dtype=torch.float64))
    moved = corr.to(device=device, dtype=torch.float32)
    assert moved.disparity_12.device.type == device.type and moved.disparity_12.dtype == torch.float32
    assert moved.valid_12.dtype == torch.bool and moved.valid_12.device.type == device.type
    assert torch.equal(moved.valid_21.cpu(), corr.valid_21)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (
            dict(disparity_12=torch.zeros(3, 4, dtype=torch.int64)),
            TypeError,
            r"disparity_12 must have a floating",
        ),
        (dict(disparity_12=[[0.0]]), TypeError, r"disparity_12 must be a torch.Tensor, got list"),
        (
            dict(disparity_12=torch.zeros(4)),
            ValueError,
            r"disparity_12 must have shape \(H, W\) or \(B, H, W\)",
        ),
        (dict(disparity_12=torch.tensor([[0.0, math.nan]])), ValueError, r"disparity_12 must be finite"),
        (
            dict(disparity_12=torch.zeros(2, 3, 4), disparity_21=torch.zeros(2, 3, 5)),
            ValueError,
            r"disparity_21 must have the shape of disparity_12 \(2, 3, 4\), got \(2, 3, 5\)",
        ),
        (
            dict(disparity_12=torch.zeros(3, 4), disparity_21=torch.full((3, 4), math.inf)),
            ValueError,
            r"disparity_21 must be finite",
        ),
    ],
)
def test_from_disparity_errors(kwargs: dict, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        correspondence_from_disparity(**kwargs)


# --- estimate_correspondence ------------------------------------------------------------


@pytest.mark.parametrize("method", ["tvl1", "ilk"])
@pytest.mark.parametrize("shift", [1.3, -2.6])
def test_recovers_subpixel_shift(method: str, shift: float) -> None:
    tex = _texture(0)
    view1 = torch.from_numpy(tex)[None]
    view2 = torch.from_numpy(_shifted(tex, shift))[None]
    corr = estimate_correspondence(view1, view2, method=method)
    assert isinstance(corr, Correspondence) and corr.shape == (1, H, W)
    assert corr.disparity_12.dtype == torch.float64 and corr.vertical_12 is not None
    v12, v21 = corr.valid_12, corr.valid_21
    assert float(v12.double().mean()) > 0.9 and float(v21.double().mean()) > 0.9
    assert float((corr.disparity_12 - shift).abs()[v12].median()) < 0.1
    assert float((corr.disparity_21 + shift).abs()[v21].median()) < 0.1
    assert float(corr.vertical_12.abs().median()) < 0.1
    # The border column whose match leaves the image is never valid.
    leaving = -1 if shift > 0 else 0
    assert not bool(v12[..., leaving].any()) and not bool(v21[..., -1 - leaving].any())


def test_occluded_band_becomes_invalid() -> None:
    """A foreground strip moves 4 px over a still background: the background it covers in
    view 2 (view-1 columns 40..43) and uncovers (view-2 columns 20..23) has no match."""
    shift = 4
    bg, fg = _texture(0), _texture(1)
    view1, view2 = bg.copy(), bg.copy()
    view1[:, 20:40] = fg[:, 20:40]
    view2[:, 20 + shift : 40 + shift] = fg[:, 20:40]
    v1, v2 = torch.from_numpy(view1)[None], torch.from_numpy(view2)[None]
    corr = estimate_correspondence(v1, v2, method="tvl1")
    inval_12, inval_21 = ~corr.valid_12[0], ~corr.valid_21[0]
    # The foreground moved by the strip's motion, the background stayed.
    assert float((corr.disparity_12[0, :, 24:36] - shift).abs().median()) < 0.1
    assert float(corr.disparity_12[0, :, 50:62].abs().median()) < 0.1
    # The regularized flow fills an occlusion smoothly, so a 1 px forward–backward check
    # flags about half of it (measured 0.54 and 0.63); the matched rest is nearly all valid.
    assert float(inval_12[:, 40 : 40 + shift].double().mean()) > 0.4
    assert float(inval_21[:, 20 : 20 + shift].double().mean()) > 0.4
    assert float(inval_12[:, 2:36].double().mean()) < 0.02
    assert float(inval_12[:, 50:62].double().mean()) < 0.02
    # A tighter threshold only removes pixels, and flags more of the occlusion.
    strict = estimate_correspondence(v1, v2, method="tvl1", threshold=0.5)
    assert not bool((strict.valid_12 & ~corr.valid_12).any())
    assert torch.equal(strict.disparity_12, corr.disparity_12)
    assert float((~strict.valid_12[0, :, 40 : 40 + shift]).double().mean()) > 0.6


def test_batched_rgb_equals_per_sample_gray() -> None:
    """(B, C, H, W) RGB input: each object is matched on its own, on the channel mean.

    float64 only: the flow runs in float64 on the channel mean either way, but float32
    disparities move borderline pixels of the consistency masks.
    """
    dtype = torch.float64
    shifts = [1.0, -1.5]
    tex = [_texture(3), _texture(4)]
    gains = torch.tensor([0.5, 1.0, 1.5], dtype=torch.float64).view(3, 1, 1)
    view1 = torch.stack([gains * torch.from_numpy(t) for t in tex]).to(dtype)
    view2 = torch.stack(
        [gains * torch.from_numpy(_shifted(t, s)) for t, s in zip(tex, shifts, strict=True)]
    ).to(dtype)
    assert view1.shape == (2, 3, H, W)
    corr = estimate_correspondence(view1, view2, method="ilk")
    assert corr.shape == (2, H, W)
    for i, s in enumerate(shifts):
        gray = estimate_correspondence(
            view1[i].mean(0, keepdim=True), view2[i].mean(0, keepdim=True), method="ilk"
        )
        for field in ("disparity_12", "disparity_21", "valid_12", "valid_21", "vertical_12"):
            assert torch.equal(getattr(corr, field)[i : i + 1], getattr(gray, field)), field
        assert float((corr.disparity_12[i] - s).abs()[corr.valid_12[i]].median()) < 0.1


def test_output_on_input_device(device: torch.device) -> None:
    tex = torch.from_numpy(_texture(2, shape=(16, 20)))[None]
    corr = estimate_correspondence(tex.float().to(device), tex.float().to(device), method="ilk")
    for t in (corr.disparity_12, corr.disparity_21, corr.valid_12, corr.valid_21, corr.vertical_12):
        assert t.device.type == device.type
    assert corr.disparity_12.dtype == torch.float32
    # Identical views: zero motion, everything valid.
    assert float(corr.disparity_12.abs().max()) < 1e-3 and bool(corr.valid_12.all())


def test_inputs_not_modified() -> None:
    tex = torch.from_numpy(_texture(2, shape=(16, 20)))[None]
    view1, view2 = tex.clone(), torch.roll(tex, 1, dims=-1)
    before = (view1.clone(), view2.clone())
    estimate_correspondence(view1, view2, method="ilk")
    assert torch.equal(view1, before[0]) and torch.equal(view2, before[1])


def test_estimate_errors() -> None:
    view = torch.rand(1, 8, 9, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    with pytest.raises(ValueError, match=r"view2 must have the shape of view1 \(1, 8, 9\), got \(1, 8, 8\)"):
        estimate_correspondence(view, view[..., :8])
    with pytest.raises(ValueError, match=r"view2 must have the shape of view1"):
        estimate_correspondence(view, view[None])
    bad = view.clone()
    bad[0, 3, 4] = math.nan
    with pytest.raises(ValueError, match=r"view1 must be finite, got 1 NaN"):
        estimate_correspondence(bad, view)
    with pytest.raises(ValueError, match=r"view2 must be finite"):
        estimate_correspondence(view, bad)
    with pytest.raises(
        ValueError,
        match=r"method must be one of \('tvl1', 'tvl1-skimage', 'ilk', 'rows', 'guided'\), got 'farneback'",
    ):
        estimate_correspondence(view, view, method="farneback")
    with pytest.raises(TypeError, match=r"view1 must have a floating dtype, got torch.uint8"):
        estimate_correspondence((view * 255).to(torch.uint8), view)
    with pytest.raises(TypeError, match=r"view2 must have a floating dtype, got torch.int64"):
        estimate_correspondence(view, view.long())
    with pytest.raises(TypeError, match=r"view1 must be a torch.Tensor, got ndarray"):
        estimate_correspondence(view.numpy(), view)
    with pytest.raises(
        ValueError, match=r"view1 must have shape \(C, H, W\) or \(B, C, H, W\), got shape \(8, 9\)"
    ):
        estimate_correspondence(view[0], view[0])


# --- indexing and collation -------------------------------------------------------------


def _batch(b: int = 4, vertical: bool = True) -> Correspondence:
    corr = correspondence_from_disparity(_smooth_disparity(b, 3, 8, seed=5))
    if not vertical:
        return corr
    return dataclasses.replace(corr, vertical_12=torch.rand(b, 3, 8), vertical_21=torch.rand(b, 3, 8))


def _assert_same_fields(a: Correspondence, b: Correspondence) -> None:
    for f in dataclasses.fields(Correspondence):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert (x is None) == (y is None), f.name
        if x is not None:
            assert torch.equal(x, y), f.name


@pytest.mark.parametrize(
    ("index", "rows"),
    [
        (2, [2]),
        (-1, [3]),
        (slice(1, 3), [1, 2]),
        ([3, 0, 0], [3, 0, 0]),
        (torch.tensor([2, 1]), [2, 1]),
        (torch.tensor([True, False, False, True]), [0, 3]),
        ([], []),
    ],
)
def test_indexing_selects_view_pairs(index: object, rows: list[int]) -> None:
    corr = _batch()
    part = corr[index]
    assert part.shape == (len(rows), 3, 8)
    for f in dataclasses.fields(Correspondence):
        assert torch.equal(getattr(part, f.name), getattr(corr, f.name)[rows]), f.name
    assert corr[1:2].vertical_12 is not None and _batch(vertical=False)[1].vertical_12 is None


def test_len_iteration_and_collate_invert_indexing() -> None:
    corr = _batch()
    assert len(corr) == 4 and len(corr[:0]) == 0
    items = list(corr)  # one B = 1 pair each
    assert [item.shape for item in items] == [(1, 3, 8)] * 4
    _assert_same_fields(Correspondence.collate(items), corr)
    _assert_same_fields(Correspondence.collate([corr[:1], corr[1:]]), corr)


def test_default_collate_and_data_loader_batch_correspondences() -> None:
    corr = _batch(vertical=False)
    views = torch.rand(4, 1, 3, 8)
    samples = [{"view": views[i], "corr": corr[i]} for i in range(4)]
    batch = torch.utils.data.default_collate(samples)
    assert batch["view"].shape == (4, 1, 3, 8)
    _assert_same_fields(batch["corr"], corr)
    loader = torch.utils.data.DataLoader(list(zip(views, corr, strict=True)), batch_size=3)
    (v0, c0), (v1, c1) = list(loader)
    assert torch.equal(v0, views[:3]) and torch.equal(v1, views[3:])
    assert c0.shape == (3, 3, 8) and c1.shape == (1, 3, 8)
    _assert_same_fields(Correspondence.collate([c0, c1]), corr)


@pytest.mark.parametrize(
    ("index", "error", "match"),
    [
        (4, IndexError, r"index 4 is out of range for a correspondence of B = 4"),
        (-5, IndexError, "out of range"),
        (
            torch.tensor([True, False]),
            IndexError,
            r"boolean index must have shape \(B,\) = \(4,\), got \(2,\)",
        ),
        (torch.tensor([0.5]), IndexError, r"\(B,\) bool or \(K,\) integer, got torch.float32"),
        (torch.zeros(2, 2, dtype=torch.long), IndexError, r"of shape \(2, 2\)"),
        (1.0, TypeError, "index must be an int, a slice, a sequence of ints or a tensor, got float"),
        (True, TypeError, "got bool"),
        ("0", TypeError, "got str"),
    ],
)
def test_indexing_errors(index: object, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        _batch()[index]


def test_collate_errors() -> None:
    corr = _batch()
    with pytest.raises(ValueError, match="non-empty sequence of Correspondence"):
        Correspondence.collate([])
    with pytest.raises(ValueError, match="non-empty sequence of Correspondence"):
        Correspondence.collate(corr)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"items\[1\] must be a Correspondence, got Tensor"):
        Correspondence.collate([corr, corr.disparity_12])  # type: ignore[list-item]
    small = correspondence_from_disparity(torch.zeros(1, 3, 5))
    with pytest.raises(ValueError, match=r"items\[1\] has \(H, W\) = \(3, 5\), items\[0\] has \(3, 8\)"):
        Correspondence.collate([corr, small])
    with pytest.raises(ValueError, match=r"items\[1\].vertical_12 is None but items\[0\].vertical_12 is set"):
        Correspondence.collate([corr[0], _batch(vertical=False)[0]])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="pinned memory needs CUDA")
def test_pin_memory() -> None:
    pinned = _batch().pin_memory()
    assert pinned.disparity_12.is_pinned() and pinned.valid_12.is_pinned()
