"""The preprocessing record of a model: its JSON and ONNX metadata round trips, and the
torch-free resize of ``eigview predict`` against the torch one of ``ViewDataset``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import skimage.io
import torch

from torch_eigview.datasets import read_view
from torch_eigview.decomposition import Eigenspace
from torch_eigview.io.images import read_image, to_unit_float
from torch_eigview.io.onnx import export_recognizer
from torch_eigview.io.onnx_metadata import OnnxModelInfo
from torch_eigview.io.preprocessing import Preprocessing, prepare_array
from torch_eigview.nn.recognition import NearestNeighborRecognizer


def test_json_round_trip_and_bad_records() -> None:
    prep = Preprocessing((24, 40), 3, unit_norm=False)
    assert Preprocessing.from_json(json.loads(json.dumps(prep.to_json()))) == prep
    assert prep.image_shape == (3, 24, 40)
    record = prep.to_json()
    for key, value, match in [
        ("size", [24], r"size \[24\] is not \[H, W\]"),
        ("channels", 2, "channels must be 1 or 3"),
        ("background", "blue", "background must be one of"),
        ("resize", "nearest", "resize must be"),
        ("unit_norm", "yes", "unit_norm must be a bool"),
    ]:
        with pytest.raises(ValueError, match=f"m.pt has a damaged preprocessing record: .*{match}"):
            Preprocessing.from_json({**record, key: value}, "m.pt")
    with pytest.raises(ValueError, match="damaged preprocessing record: 'channels' is missing"):
        Preprocessing.from_json({k: v for k, v in record.items() if k != "channels"}, "m.pt")
    with pytest.raises(ValueError, match=r"size must be \(H, W\) with ints >= 1, got \(0, 4\)"):
        Preprocessing((0, 4), 1)


@pytest.mark.parametrize(
    ("shape", "size", "channels"),
    [((40, 56), (20, 28), 1), ((17, 23), (32, 30), 1), ((30, 30, 3), (16, 20), 1), ((12, 14), (12, 14), 3)],
)
def test_prepare_array_equals_the_torch_read(
    tmp_path: Path, shape: tuple[int, ...], size: tuple[int, int], channels: int
) -> None:
    path = tmp_path / "a.png"
    skimage.io.imsave(
        path, np.random.default_rng(0).integers(0, 256, shape, dtype=np.uint8), check_contrast=False
    )
    prep = Preprocessing(size, channels)
    got = prepare_array(to_unit_float(read_image(path)), prep)
    want, _ = read_view(path, size=size, channels=channels)
    assert got.shape == prep.image_shape and got.dtype == np.float32
    np.testing.assert_allclose(got, want.numpy(), atol=5e-6, rtol=0)


def test_prepare_array_refuses_other_layouts() -> None:
    with pytest.raises(ValueError, match=r"image must be \(C, H, W\) with C 1 or 3, got shape \(2, 4, 4\)"):
        prepare_array(np.zeros((2, 4, 4), np.float32), Preprocessing((4, 4), 1))


def test_onnx_metadata_carries_it() -> None:
    info = OnnxModelInfo("recognizer", (1, 8, 6), 3, True, ("a", "b"), "NearestNeighborRecognizer")
    props = info.to_props()
    assert "preprocessing" not in props  # a model without one keeps its former metadata
    with_prep = OnnxModelInfo(**{**info.__dict__, "preprocessing": Preprocessing((8, 6), 1)})
    assert OnnxModelInfo.from_props(with_prep.to_props()) == with_prep
    bad = {**with_prep.to_props(), "preprocessing": Preprocessing((8, 7), 1).to_prop()}
    with pytest.raises(
        ValueError,
        match=r"damaged torch_eigview metadata: preprocessing must give images of image_shape \[1, 8, 6\], got \[1, 8, 7\]",
    ):
        OnnxModelInfo.from_props(bad)


def test_export_refuses_preprocessing_of_another_shape(tmp_path: Path) -> None:
    views = torch.rand(4, 1, 8, 6)
    rec = NearestNeighborRecognizer.from_views(
        Eigenspace(2).fit(views).to_module(), views, torch.arange(4), torch.zeros(4)
    )
    with pytest.raises(
        ValueError,
        match=r"preprocessing gives images \(C, H, W\)=\(3, 8, 6\), but the model takes \(1, 8, 6\)",
    ):
        export_recognizer(rec, tmp_path / "m.onnx", preprocessing=Preprocessing((8, 6), 3))
    with pytest.raises(TypeError, match="preprocessing must be a Preprocessing"):
        export_recognizer(rec, tmp_path / "m.onnx", preprocessing={"size": [8, 6]})  # type: ignore[arg-type]
    assert not (tmp_path / "m.onnx").exists()


def test_inverted_alpha_refused_by_both_readers(tmp_path: Path) -> None:
    """An alpha channel that marks the whole border as object (an inverted mask) is refused by
    the torch reader (read_view) and the numpy one (prepare_file) alike, naming the file; one
    that marks half of it is read with a warning."""
    from torch_eigview.datasets import background_rule
    from torch_eigview.io.preprocessing import Preprocessing, prepare_file

    gray = np.zeros((16, 16), np.uint8)
    gray[5:11, 5:11] = 200
    inside = np.zeros((16, 16), bool)
    inside[5:11, 5:11] = True
    prep = Preprocessing((16, 16), 1, background="auto")

    def write(name: str, alpha: np.ndarray) -> Path:
        path = tmp_path / f"{name}.png"
        rgba = np.dstack([gray, gray, gray, alpha.astype(np.uint8) * 255])
        skimage.io.imsave(path, rgba, check_contrast=False)
        return path

    inverted = write("inverted", ~inside)
    refused = r"alpha channel of .*inverted\.png marks 100% of the image border as object: is it inverted"
    with pytest.raises(ValueError, match=refused):
        prepare_file(inverted, prep)
    with pytest.raises(ValueError, match=refused):
        read_view(inverted, background=background_rule("auto"))
    half = write("half", inside | (np.arange(16) < 8)[None, :])
    with pytest.warns(UserWarning, match=r"alpha channel of .*half\.png marks \d+% of the image border"):
        prepare_file(half, prep)
