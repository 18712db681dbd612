"""ONNX export of any module on images (an ``nn.Sequential`` of the layer and a head), and the
TorchScript-based exporter (``dynamo=False``), each checked in onnxruntime against eager."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import onnxruntime
import pytest
import torch
from torch import nn

from torch_eigview import EigenProjection, Eigenspace, KernelEigenspace, NearestNeighborRecognizer
from torch_eigview.io.onnx import compare_with_eager, export_onnx, export_recognizer, read_metadata

from tests.helpers import rand

IMAGE_SHAPE = (1, 6, 8)
# The TorchScript exporter is deprecated from torch 2.9 on, and says so (twice). It takes
# well under a second here; the dynamo exporter a few seconds (marked slow).
LEGACY = pytest.mark.filterwarnings(
    "ignore:You are using the legacy TorchScript-based ONNX export",
    "ignore:The feature will be removed:DeprecationWarning",
)
EXPORTERS = [
    pytest.param(True, id="dynamo", marks=pytest.mark.slow),
    pytest.param(False, id="torchscript", marks=LEGACY),
]


def projection(unit_norm: bool = True) -> EigenProjection:
    x = rand(20, *IMAGE_SHAPE, seed=0)
    return Eigenspace(5).fit(x).to_module(unit_norm=unit_norm).float()


def model() -> nn.Sequential:
    """The frozen projection, then a head: what a user trains and ships."""
    torch.manual_seed(0)
    return nn.Sequential(projection(), nn.Linear(5, 3)).eval()


def run(path: Path, x: torch.Tensor) -> np.ndarray:
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (out,) = session.run(None, {session.get_inputs()[0].name: x.numpy()})
    return out


@pytest.mark.parametrize("dynamo", EXPORTERS)
def test_sequential_matches_eager(tmp_path: Path, dynamo: bool) -> None:
    seq = model()
    path = tmp_path / "seq.onnx"
    info = export_onnx(seq, path, image_shape=IMAGE_SHAPE, dynamo=dynamo)
    assert info.module == "Sequential" and info.image_shape == IMAGE_SHAPE
    assert info.n_components == 3 and info.unit_norm and info.kind == "projection"
    assert read_metadata(path) == info
    for batch in (1, 7):  # the batch axis is dynamic
        x = rand(batch, *IMAGE_SHAPE, seed=batch, dtype=torch.float32)
        assert run(path, x).shape == (batch, 3)
        assert compare_with_eager(seq, path, x)["max_rel_err"] <= 1e-5


@pytest.mark.slow
def test_example_input_gives_the_shape(tmp_path: Path) -> None:
    seq = model()
    one = rand(1, *IMAGE_SHAPE, seed=3, dtype=torch.float64)  # one image, float64: cast, traced as two
    info = export_onnx(seq, tmp_path / "seq.onnx", example_input=one)
    assert info.image_shape == IMAGE_SHAPE
    assert (
        compare_with_eager(seq, tmp_path / "seq.onnx", rand(4, *IMAGE_SHAPE, seed=4))["max_rel_err"] <= 1e-5
    )


@pytest.mark.parametrize("unit_norm", [True, False], ids=["unit-norm", "raw"])
@pytest.mark.parametrize("fold", [True, False], ids=["folded", "as-written"])
@LEGACY
def test_torchscript_exporter_projection(tmp_path: Path, unit_norm: bool, fold: bool) -> None:
    layer = projection(unit_norm)
    info = export_onnx(layer, tmp_path / "p.onnx", fold=fold, dynamo=False)
    assert info.n_components == 5 and info.unit_norm == unit_norm
    x = rand(6, *IMAGE_SHAPE, seed=5, dtype=torch.float32)
    assert compare_with_eager(layer, tmp_path / "p.onnx", x)["max_rel_err"] <= 1e-5


@LEGACY
def test_torchscript_exporter_recognizer_and_kernel(tmp_path: Path) -> None:
    kernel = KernelEigenspace(4, kernel="rbf").fit(rand(16, *IMAGE_SHAPE, seed=0)).to_module()
    gallery = rand(6, *IMAGE_SHAPE, seed=2)
    for name, layer in (("linear", projection()), ("kernel", kernel)):
        rec = NearestNeighborRecognizer.from_views(
            layer.double(), gallery, torch.tensor([4, 7] * 3), torch.arange(6.0)
        )
        info = export_recognizer(rec, tmp_path / f"{name}.onnx", dynamo=False)
        assert info.label_names == ("4", "7"), name
        report = compare_with_eager(rec, tmp_path / f"{name}.onnx", gallery.float())
        assert report["label_agreement"] == 1.0 and report["max_pose_diff"] == 0.0, name


@LEGACY
def test_torch_onnx_export_torchscript_on_the_layer(tmp_path: Path) -> None:
    """torch.onnx.export itself, TorchScript-based (the default on torch 2.5-2.8): the layer's
    extra state (a dict) used to crash it with "'dict' object has no attribute 'detach'"."""
    for name, module in (("layer", projection()), ("sequential", model())):
        buffer = io.BytesIO()
        x = rand(3, *IMAGE_SHAPE, seed=6, dtype=torch.float32)
        torch.onnx.export(
            module,
            (x,),
            buffer,
            dynamo=False,
            input_names=["x"],
            dynamic_axes={"x": {0: "b"}},
            opset_version=18,
        )
        (tmp_path / name).write_bytes(buffer.getvalue())
        got = run(tmp_path / name, x)
        with torch.no_grad():
            want = module(x).numpy()
        assert np.abs(got - want).max() <= 1e-5 * np.abs(want).max(), name
    # The extra state is left out only while exporting: state_dict keeps it otherwise.
    assert "_extra_state" in projection().state_dict()


class _Images(nn.Module):
    """Returns its input: not a (B, k) output."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * 2


def test_any_module_errors(tmp_path: Path) -> None:
    path = tmp_path / "x.onnx"
    with pytest.raises(
        ValueError, match=r"Sequential\.image_shape is None.*pass image_shape=\(C, H, W\) or example_input"
    ):
        export_onnx(model(), path)
    with pytest.raises(
        ValueError,
        match=r"the image shapes differ: image_shape=\(1, 8, 6\), EigenProjection\.image_shape=\(1, 6, 8\)",
    ):
        export_onnx(projection(), path, image_shape=(1, 8, 6))
    with pytest.raises(ValueError, match=r"image_shape=\(1, 6, 8\), example_input's \(C, H, W\)=\(1, 8, 6\)"):
        export_onnx(model(), path, image_shape=IMAGE_SHAPE, example_input=torch.zeros(2, 1, 8, 6))
    with pytest.raises(
        ValueError, match=r"example_input must have shape \(B, C, H, W\), got shape \(2, 48\)"
    ):
        export_onnx(model(), path, example_input=torch.zeros(2, 48))
    with pytest.raises(ValueError, match=r"example_input must hold at least one image"):
        export_onnx(model(), path, example_input=torch.zeros(0, *IMAGE_SHAPE))
    with pytest.raises(TypeError, match=r"example_input must be a torch\.Tensor, got ndarray"):
        export_onnx(model(), path, example_input=np.zeros((2, *IMAGE_SHAPE)))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"image_shape must be None or a \(C, H, W\) tuple of 3 ints, got 48"):
        export_onnx(model(), path, image_shape=48)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"image_shape=0 must be >= 1"):
        export_onnx(model(), path, image_shape=(0, 6, 8))
    with pytest.raises(
        ValueError,
        match=r"_Images must map \(B, C, H, W\) images to one \(B, k\) tensor.*shape \(2, 1, 6, 8\)",
    ):
        export_onnx(_Images(), path, image_shape=IMAGE_SHAPE)
    assert not path.exists()


def test_opset_above_the_installed_onnx_is_refused(tmp_path: Path) -> None:
    """An opset the exporter cannot write is an error naming it, not a graph of another opset."""
    import onnx

    newest = onnx.defs.onnx_opset_version()
    layer = EigenProjection.from_tensors(torch.zeros(12), torch.eye(3, 12), image_shape=(1, 3, 4))
    with pytest.raises(ValueError, match=rf"opset_version={newest + 1} must be <= {newest}"):
        export_onnx(layer, tmp_path / "m.onnx", opset_version=newest + 1)
    assert not (tmp_path / "m.onnx").exists()
