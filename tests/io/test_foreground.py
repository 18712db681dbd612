"""The torch-free foreground of ``eigview predict --onnx`` against ``read_view`` with a
:class:`~torch_eigview.datasets.background.BackgroundModel`, on rendered backdrop images."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import skimage.io

from torch_eigview.datasets import (
    Backdrop,
    BackgroundModel,
    OrthographicCamera,
    make_object,
    read_view,
    render,
)
from torch_eigview.io.foreground import colour_in_channels, estimate_foreground
from torch_eigview.io.images import read_image, to_unit_float
from torch_eigview.io.preprocessing import Preprocessing, prepare_array


@pytest.mark.parametrize(("name", "azimuth"), [("head", 0.0), ("egg", 35.0), ("cylinder", 80.0)])
def test_prepare_array_masks_as_the_background_model(tmp_path: Path, name: str, azimuth: float) -> None:
    """Same size: the same masks and pixels; resized (Pillow against torch): pixels to
    float32 rounding (measured: at most 1.1e-6 over 54 cases, no mask pixel differs)."""
    r = render(make_object(name, 0), azimuth, OrthographicCamera(48, scale=14), backdrop=Backdrop())
    path = tmp_path / "a.png"
    rgb = np.round(r.image.permute(1, 2, 0).numpy() * 255).astype(np.uint8)
    skimage.io.imsave(path, rgb, check_contrast=False)
    image = to_unit_float(read_image(path))
    for size, channels in [((48, 48), 3), ((32, 32), 1), ((40, 56), 3)]:
        prep = Preprocessing(size, channels, background="auto")
        got = prepare_array(image, prep)
        want, fg = read_view(path, size=size, channels=channels, background=BackgroundModel())
        np.testing.assert_allclose(got, want.numpy(), atol=5e-6, rtol=0)
        assert np.array_equal(got.max(axis=0) > 0, (want.max(dim=0).values > 0).numpy())
        if size == (48, 48):  # no resize: the model's mask itself
            assert np.array_equal(estimate_foreground(image), fg[0].numpy())
            assert (fg[0].numpy() & r.mask.numpy()).sum() >= 0.9 * r.mask.numpy().sum()


def test_colours_and_errors() -> None:
    assert colour_in_channels((0.5,), 3) == (0.5, 0.5, 0.5)
    assert colour_in_channels((1.0, 1.0, 1.0), 1) == pytest.approx((1.0,))
    assert colour_in_channels((0.1, 0.2, 0.3), 3) == (0.1, 0.2, 0.3)
    flat = np.full((3, 8, 8), 0.5, np.float32)
    with pytest.raises(ValueError, match=r"\(given\) leaves no object in the image"):
        estimate_foreground(flat, (0.5, 0.5, 0.5))
    with pytest.raises(ValueError, match=r"background=\(0.5,\) must hold C=3 values"):
        estimate_foreground(flat, (0.5,))
    prep = Preprocessing((8, 8), 3, background="auto")
    with pytest.raises(ValueError, match="the mask is all background"):
        prepare_array(flat, prep, np.zeros((8, 8), bool))
    with pytest.raises(ValueError, match=r"mask must have the image's size \(H, W\)=\(8, 8\)"):
        prepare_array(flat, prep, np.ones((8, 9), bool))
