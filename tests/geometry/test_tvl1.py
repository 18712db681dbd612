"""TV-L1 in torch against scikit-image's optical_flow_tvl1: the pyramid, the flow upsampling,
the flow on rendered and COIL-20 views, batching, dtype, device and bad input."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import ndimage as ndi
from skimage.registration import optical_flow_tvl1
from skimage.transform import pyramid_reduce

from torch_eigview.datasets.cameras import OrthographicCamera
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.datasets.renderer import render_views
from torch_eigview.datasets.shapes import make_object
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.tvl1 import _pyramid, _upsample_flow, max_magnitude, tvl1_flow

FAST = {"num_warp": 3, "num_iter": 5}  # the synthesis preset


def _rendered(alpha: float, size: int = 64) -> tuple[np.ndarray, np.ndarray]:
    views = render_views(make_object("head"), [0.0, alpha], OrthographicCamera(size))[:, 0]
    return views[0].double().numpy(), views[1].double().numpy()


def _agree(ours: np.ndarray, ref: np.ndarray) -> None:
    """The two flows agree up to float32 rounding amplified by the iterations: a few pixels of
    a hard pair differ by up to a few hundredths of a pixel, the bulk by 1e-5."""
    diff = np.abs(ours - ref)
    assert float(diff.mean()) < 1e-3, float(diff.mean())
    assert float(np.percentile(diff, 99)) < 1e-2, float(np.percentile(diff, 99))
    assert float(diff.max()) < 0.5, float(diff.max())


def test_pyramid_is_scikit_images() -> None:
    image = np.random.default_rng(0).random((70, 133)).astype(np.float32)
    ours = _pyramid(torch.from_numpy(image)[None])
    ref = [image]
    while min(ref[-1].shape) > 32:
        ref.append(pyramid_reduce(ref[-1], 2, channel_axis=None))
    assert [tuple(level.shape[-2:]) for level in ours] == [r.shape for r in ref[::-1]]
    for level, r in zip(ours, ref[::-1], strict=True):
        np.testing.assert_allclose(level[0].numpy(), r, atol=5e-6)


@pytest.mark.parametrize(
    ("small", "large"), [((16, 16), (32, 32)), ((17, 33), (33, 65)), ((9, 32), (18, 64))]
)
def test_flow_upsampling_is_ndimage_zoom(small: tuple[int, int], large: tuple[int, int]) -> None:
    flow = np.random.default_rng(1).standard_normal((2, *small)).astype(np.float32)
    scale = [n / o for n, o in zip(large, small, strict=True)]
    ref = np.array(scale, dtype=np.float32)[:, None, None] * ndi.zoom(
        flow, [1, *scale], order=0, mode="nearest", prefilter=False
    )
    ours = _upsample_flow(torch.from_numpy(flow)[None], large)[0].numpy()
    np.testing.assert_allclose(ours, ref, rtol=1e-6)


@pytest.mark.parametrize("options", [FAST, {}], ids=["fast", "defaults"])
@pytest.mark.parametrize("alpha", [8.0, 30.0])
def test_flow_is_scikit_images_on_rendered_views(options: dict[str, int], alpha: float) -> None:
    a, b = _rendered(alpha)
    ref = optical_flow_tvl1(a, b, **options)
    ours = tvl1_flow(torch.from_numpy(a).float(), torch.from_numpy(b).float(), **options)
    assert ours.shape == (2, 64, 64) and ours.dtype == torch.float32
    _agree(ours.numpy(), ref)


@pytest.mark.parametrize(("obj", "alpha"), [(1, 10.0), (14, 10.0), (5, 45.0)])
def test_flow_is_scikit_images_on_coil(folder: CoilFolder, obj: int, alpha: float) -> None:
    seeds = folder.images(obj, [0.0, alpha]).double().mean(1)
    a, b = seeds[0].numpy(), seeds[1].numpy()
    for options in (FAST, {}):
        ours = tvl1_flow(seeds[:1].float(), seeds[1:].float(), **options)[0]
        _agree(ours.numpy(), optical_flow_tvl1(a, b, **options))


def test_batch_is_pair_by_pair() -> None:
    """Each pair stops on its own: an identical pair (stops after one warp) beside moving ones."""
    a, b = _rendered(10.0)
    c, d = _rendered(25.0)
    ref = torch.from_numpy(np.stack([a, c, a])).float()
    mov = torch.from_numpy(np.stack([b, d, a])).float()
    batch = tvl1_flow(ref, mov)
    for i in range(3):
        torch.testing.assert_close(batch[i], tvl1_flow(ref[i], mov[i]), atol=1e-5, rtol=0)
    assert float(batch[2].abs().max()) < 1e-4  # no motion (up to the warp's rounding)


def test_dtype_and_device(device: torch.device) -> None:
    a, b = _rendered(10.0, size=48)
    ref = tvl1_flow(torch.from_numpy(a).float(), torch.from_numpy(b).float(), **FAST)
    for dtype in (torch.float32, torch.float64):
        out = tvl1_flow(torch.from_numpy(a).to(device, dtype), torch.from_numpy(b).to(device, dtype), **FAST)
        assert out.dtype == dtype and out.device.type == device.type
        torch.testing.assert_close(out.cpu().float(), ref, atol=2e-3, rtol=0)
    assert tvl1_flow(torch.zeros(0, 8, 8), torch.zeros(0, 8, 8)).shape == (0, 2, 8, 8)


def test_inputs_not_modified() -> None:
    a, b = (torch.from_numpy(v).float() for v in _rendered(10.0, size=32))
    a0, b0 = a.clone(), b.clone()
    tvl1_flow(a, b, **FAST)
    assert torch.equal(a, a0) and torch.equal(b, b0)


def test_correspondence_is_the_reference_one() -> None:
    """estimate_correspondence: "tvl1" (torch) and "tvl1-skimage" give the same matches and masks."""
    views = render_views(make_object("head"), [0.0, 10.0], OrthographicCamera(64))
    ours = estimate_correspondence(views[:1], views[1:], **FAST)
    ref = estimate_correspondence(views[:1], views[1:], method="tvl1-skimage", **FAST)
    for name in ("disparity_12", "disparity_21", "vertical_12", "vertical_21"):
        torch.testing.assert_close(getattr(ours, name), getattr(ref, name), atol=0.05, rtol=0)
    for name in ("valid_12", "valid_21"):
        assert float((getattr(ours, name) != getattr(ref, name)).float().mean()) < 0.002


@pytest.mark.parametrize(
    ("args", "kwargs", "error", "match"),
    [
        (
            (np.zeros((8, 8)), torch.zeros(8, 8)),
            {},
            TypeError,
            "reference must be a torch.Tensor, got ndarray",
        ),
        (
            (torch.zeros(8, 8), torch.zeros(8, 9)),
            {},
            ValueError,
            r"moving must have the shape of reference \(8, 8\)",
        ),
        ((torch.zeros(1, 1, 8, 8), torch.zeros(1, 1, 8, 8)), {}, ValueError, "reference must have"),
        (
            (torch.zeros(1, 8), torch.zeros(1, 8)),
            {},
            ValueError,
            r"at least 2 x 2 pixels, got shape \(1, 8\)",
        ),
        ((torch.full((8, 8), float("nan")), torch.zeros(8, 8)), {}, ValueError, "reference must be finite"),
        (
            (torch.zeros(8, 8), torch.full((8, 8), 1e30)),
            {},
            ValueError,
            "moving holds values of magnitude 1e",
        ),
        ((torch.zeros(8, 8), torch.zeros(8, 8)), {"num_warp": 0}, ValueError, "num_warp"),
        ((torch.zeros(8, 8), torch.zeros(8, 8)), {"attachment": -1.0}, ValueError, "attachment"),
        ((torch.zeros(8, 8), torch.zeros(8, 8)), {"tol": float("nan")}, ValueError, "tol"),
    ],
)
def test_bad_input(args: tuple[object, object], kwargs: dict[str, object], error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        tvl1_flow(*args, **kwargs)  # type: ignore[arg-type]


def test_max_magnitude() -> None:
    # Differences of two values squared, two of them summed: 8 M² stays finite.
    assert max_magnitude(torch.float32) ** 2 * 8 < torch.finfo(torch.float32).max
    assert max_magnitude(torch.float64) > max_magnitude(torch.float32)


def test_pyramid_depth_follows_min_size() -> None:
    image = torch.rand(1, 128, 96)
    assert [tuple(p.shape[-2:]) for p in _pyramid(image)] == [(32, 24), (64, 48), (128, 96)]
    assert len(_pyramid(image, 8)) == 4 and len(_pyramid(image, 64)) == 1
    with pytest.raises(ValueError, match="min_size"):
        tvl1_flow(image[0], image[0], min_size=0)


def test_prefilter_is_scikit_images() -> None:
    a, b = _rendered(10.0)
    ref = optical_flow_tvl1(a, b, prefilter=True, **FAST)
    ours = tvl1_flow(torch.from_numpy(a).float(), torch.from_numpy(b).float(), prefilter=True, **FAST)
    _agree(ours.numpy(), ref)
    flow = torch.from_numpy(np.random.default_rng(2).standard_normal((1, 2, 9, 13)).astype(np.float32))
    from torch_eigview.geometry.tvl1 import _median3

    np.testing.assert_array_equal(
        _median3(flow)[0].numpy(), ndi.median_filter(flow[0].numpy(), size=(1, 3, 3))
    )


def test_inputs_that_require_grad() -> None:
    a, b = (torch.from_numpy(v).float() for v in _rendered(10.0, size=32))
    out = tvl1_flow(a.requires_grad_(), b, **FAST)
    assert not out.requires_grad
    torch.testing.assert_close(out, tvl1_flow(a.detach(), b, **FAST))
