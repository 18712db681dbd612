"""ONNX export (projection, recognizer, kernel projection) against eager PyTorch, and the
``eigview export`` / ``eigview predict`` commands (predict without torch)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import onnx
import onnxruntime
import pytest
import skimage.io
import torch
from torch import nn

import torch_eigview
from torch_eigview import CoilFolder, EigenProjection, Eigenspace, NearestNeighborRecognizer, NotFittedError
from torch_eigview.apps.cli import main
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.io.checkpoint import save_recognizer
from torch_eigview.io.onnx import (
    FoldedProjection,
    compare_with_eager,
    export_onnx,
    export_projection,
    export_recognizer,
    read_metadata,
)
from torch_eigview.io.onnx_metadata import FORMAT_VERSION, OnnxModelInfo

IMAGE_SHAPE = (1, 6, 8)
OBJECTS = [1, 2, 3]
TEST_ANGLES = [float(a) for a in range(-45, 50, 5)]


def rand(*shape: int, seed: int) -> torch.Tensor:
    return torch.rand(*shape, generator=torch.Generator().manual_seed(seed))


def make_projection(unit_norm: bool) -> EigenProjection:
    x = rand(20, *IMAGE_SHAPE, seed=0).double()
    flat = x.flatten(1)
    space = Eigenspace(5).fit(flat / flat.norm(dim=1, keepdim=True) if unit_norm else flat)
    return EigenProjection.from_tensors(
        space.mean_.float(), space.components_.float(), image_shape=IMAGE_SHAPE, unit_norm=unit_norm
    )


def session(path: Path) -> onnxruntime.InferenceSession:
    return onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])


@pytest.fixture(scope="module")
def coil_model(folder: CoilFolder, tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """A recognizer of COIL objects 1-3 (dense gallery: no flow, fast), saved and exported."""
    result = CoilExperiment(method="dense", objects=OBJECTS, components=8).run(folder)
    out = tmp_path_factory.mktemp("onnx")
    save_recognizer(result.recognizer, out / "model.pt", {"command": "test"})
    export_recognizer(result.recognizer, out / "recognizer.onnx")
    export_projection(result.recognizer.projection, out / "projection.onnx")
    images = torch.cat([folder.images(obj, TEST_ANGLES) for obj in OBJECTS])
    return {"recognizer": result.recognizer, "dir": out, "images": images}


@pytest.mark.slow
@pytest.mark.parametrize("unit_norm", [True, False], ids=["unit-norm", "raw"])
@pytest.mark.parametrize("fold", [True, False], ids=["folded", "as-written"])
def test_projection_matches_eager(tmp_path: Path, unit_norm: bool, fold: bool) -> None:
    projection = make_projection(unit_norm)
    path = tmp_path / "p.onnx"
    info = export_projection(projection, path, fold=fold)
    assert info == OnnxModelInfo("projection", IMAGE_SHAPE, 5, unit_norm, (), "EigenProjection")
    assert read_metadata(path) == info
    sess = session(path)
    assert [i.name for i in sess.get_inputs()] == ["images"]
    assert [o.name for o in sess.get_outputs()] == ["coefficients"]
    for batch in (1, 7):  # the batch axis is dynamic
        x = rand(batch, *IMAGE_SHAPE, seed=batch)
        (got,) = sess.run(None, {"images": x.numpy()})
        assert got.shape == (batch, 5) and got.dtype == np.float32
        assert compare_with_eager(projection, path, x, session=sess)["max_rel_err"] <= 1e-5
    # The folded module is the same map in eager PyTorch too.
    x = rand(4, *IMAGE_SHAPE, seed=9)
    torch.testing.assert_close(FoldedProjection(projection)(x), projection(x), atol=1e-6, rtol=1e-5)


@pytest.mark.slow
def test_metadata_props_in_the_graph(tmp_path: Path) -> None:
    path = tmp_path / "p.onnx"
    export_projection(make_projection(True), path)
    model = onnx.load(str(path))
    props = {p.key: p.value for p in model.metadata_props}
    assert json.loads(props["image_shape"]) == list(IMAGE_SHAPE)
    assert props["n_components"] == "5" and json.loads(props["unit_norm"]) is True
    assert json.loads(props["label_names"]) == []
    assert props["format_version"] == str(FORMAT_VERSION)
    assert model.opset_import[0].version >= 18 or any(o.version >= 18 for o in model.opset_import)


@pytest.mark.slow
@pytest.mark.coil
def test_recognizer_matches_eager_on_coil(coil_model: dict[str, object]) -> None:
    out = Path(coil_model["dir"])  # type: ignore[arg-type]
    rec, images = coil_model["recognizer"], coil_model["images"]
    assert isinstance(images, torch.Tensor) and images.shape[0] == len(OBJECTS) * 19
    report = compare_with_eager(rec, out / "recognizer.onnx", images)  # type: ignore[arg-type]
    assert report["label_agreement"] == 1.0
    assert report["max_pose_diff"] == 0.0
    # Absolute: |z|² − 2z·g + |g|² cancels in float32 where a test view is in the gallery
    # (distance 0 reads ~sqrt(1e-7)), in eager PyTorch as in onnxruntime.
    assert report["max_distance_diff"] <= 1e-3
    coefficients = compare_with_eager(rec.projection, out / "projection.onnx", images)  # type: ignore[union-attr]
    assert coefficients["max_rel_err"] <= 1e-5

    info = read_metadata(out / "recognizer.onnx")
    assert info.kind == "recognizer" and info.label_names == ("1", "2", "3")
    assert info.image_shape == (1, 128, 128) and info.n_components == 8 and info.unit_norm
    sess = session(out / "recognizer.onnx")
    assert [o.name for o in sess.get_outputs()] == ["label_index", "pose", "distance"]
    ops = {node.op_type for node in onnx.load(str(out / "recognizer.onnx")).graph.node}
    assert {"MatMul", "ArgMin"} <= ops and not ops & {"Loop", "Scan", "If"}


@pytest.mark.slow
def test_kernel_projection(tmp_path: Path) -> None:
    kernel_eigenspace = getattr(torch_eigview, "KernelEigenspace", None)
    if kernel_eigenspace is None or getattr(torch_eigview, "KernelProjection", None) is None:
        pytest.skip("torch_eigview.KernelProjection does not exist yet (kernel PCA in progress)")
    layer = kernel_eigenspace(n_components=4).fit(rand(16, *IMAGE_SHAPE, seed=0).double()).to_module()
    path = tmp_path / "k.onnx"
    info = export_projection(layer, path)
    assert info.kind == "projection" and info.n_components == 4 and info.image_shape == IMAGE_SHAPE
    x = rand(5, *IMAGE_SHAPE, seed=1)
    assert compare_with_eager(layer, path, x)["max_rel_err"] <= 1e-5
    # A recognizer over the kernel projection exports too (its layer as it is, not folded).
    gallery = rand(6, *IMAGE_SHAPE, seed=2).double()
    rec = NearestNeighborRecognizer.from_views(layer, gallery, torch.tensor([4, 7] * 3), torch.arange(6.0))
    info = export_recognizer(rec, tmp_path / "kr.onnx")
    assert info.kind == "recognizer" and info.label_names == ("4", "7") and info.n_components == 4
    assert compare_with_eager(rec, tmp_path / "kr.onnx", gallery.float())["label_agreement"] == 1.0


class _Toy(nn.Module):
    """Any module with image_shape and n_components exports (the kernel layer's path)."""

    def __init__(self) -> None:
        super().__init__()
        self.image_shape = IMAGE_SHAPE
        self.n_components = 3
        self.register_buffer("w", rand(48, 3, seed=3))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.tanh(x.flatten(1) @ self.w)


def test_generic_module(tmp_path: Path) -> None:
    toy = _Toy().double()
    info = export_onnx(toy, tmp_path / "t.onnx")
    assert info.module == "_Toy" and info.n_components == 3 and not info.unit_norm
    assert toy.w.dtype == torch.float64  # exported from a float32 copy, the module untouched
    assert (
        compare_with_eager(toy.float(), tmp_path / "t.onnx", rand(3, *IMAGE_SHAPE, seed=4))["max_rel_err"]
        <= 1e-5
    )


def test_export_errors(tmp_path: Path) -> None:
    path = tmp_path / "x.onnx"
    with pytest.raises(TypeError, match=r"model must be an nn\.Module"):
        export_onnx("model.pt", path)
    with pytest.raises(NotFittedError):
        export_onnx(Eigenspace(3), path)
    no_shape = EigenProjection.from_tensors(torch.zeros(48), torch.eye(48)[:2])
    with pytest.raises(ValueError, match="image_shape is None"):
        export_projection(no_shape, path)
    with pytest.raises(ValueError, match="opset_version=17 must be >= 18"):
        export_projection(make_projection(True), path, opset_version=17)
    with pytest.raises(TypeError, match="recognizer must be a NearestNeighborRecognizer"):
        export_recognizer(make_projection(True), path)  # type: ignore[arg-type]
    assert not path.exists()


@pytest.mark.parametrize(
    ("props", "message"),
    [
        ({}, "was not exported by torch_eigview"),
        ({"format": "torch_eigview.io.onnx", "format_version": "99"}, "format version '99'"),
        ({"format": "torch_eigview.io.onnx", "format_version": "2", "kind": "recognizer"}, "damaged"),
    ],
    ids=["foreign", "version", "damaged"],
)
def test_metadata_errors(props: dict[str, str], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        OnnxModelInfo.from_props(props, source="m.onnx")


# --- the commands ---------------------------------------------------------------------------

PREDICT_NO_TORCH = (
    "import sys; from torch_eigview.apps.cli import main; rc = main(sys.argv[1:]); "
    "assert 'torch' not in sys.modules, 'predict imported torch'; sys.exit(rc)"
)


@pytest.fixture(scope="module")
def image_files(folder: CoilFolder, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Three real COIL views, a text file named .png, and an image of the wrong size."""
    out = tmp_path_factory.mktemp("images")
    files = {}
    for obj, pose in ((1, 0), (2, 3), (3, 70)):  # pose indices: 0, 15 and 350 degrees
        files[f"{obj}"] = folder.root / f"obj{obj}__{pose}.png"
    files["broken"] = out / "broken.png"
    files["broken"].write_text("not an image\n")
    files["small"] = out / "small.png"
    skimage.io.imsave(files["small"], np.zeros((32, 32), np.uint8), check_contrast=False)
    return files


@pytest.mark.slow
@pytest.mark.coil
def test_predict_without_torch(
    coil_model: dict[str, object], image_files: dict[str, Path], tmp_path: Path
) -> None:
    onnx_path = Path(coil_model["dir"]) / "recognizer.onnx"  # type: ignore[arg-type]
    good = [str(image_files[k]) for k in ("1", "2", "3")]
    argv = ["predict", "--onnx", str(onnx_path), good[0], str(image_files["broken"]), *good[1:]]
    argv += [str(image_files["small"]), "--json", str(tmp_path / "p.json"), "--debug-modules"]
    proc = subprocess.run(
        [sys.executable, "-c", PREDICT_NO_TORCH, *argv], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 1, proc.stderr  # two bad files among good ones: reported, not fatal
    assert "torch imported: False" in proc.stderr
    assert "broken.png is not an image file that can be read" in proc.stderr
    assert "has shape (C, H, W)=(1, 32, 32), but the model expects (1, 128, 128)" in proc.stderr
    assert "2 of 5 images failed" in proc.stderr

    records = json.loads((tmp_path / "p.json").read_text())
    assert [r["image"] for r in records] == good
    assert set(records[0]) == {"image", "label", "pose", "distance"}
    rec = coil_model["recognizer"]
    from torch_eigview.io.images import read_image, to_unit_float

    x = torch.from_numpy(np.stack([to_unit_float(read_image(p)) for p in good]))
    want = rec.predict(x)  # type: ignore[union-attr]
    assert [r["label"] for r in records] == [str(v) for v in want.labels.tolist()]
    assert [r["pose"] for r in records] == pytest.approx(want.poses.tolist(), abs=1e-4)
    assert [r["distance"] for r in records] == pytest.approx(want.distances.tolist(), rel=1e-4, abs=1e-3)
    lines = proc.stdout.splitlines()
    assert len(lines) == 3 and lines[0].startswith(good[0]) and f"label {records[0]['label']}" in lines[0]


@pytest.mark.slow
@pytest.mark.coil
def test_predict_all_good_exits_zero(
    coil_model: dict[str, object], image_files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    onnx_path = Path(coil_model["dir"]) / "recognizer.onnx"  # type: ignore[arg-type]
    assert main(["predict", "--onnx", str(onnx_path), str(image_files["1"])]) == 0
    assert "label 1" in capsys.readouterr().out


def _exit(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    with pytest.raises(SystemExit) as info:
        main(argv)
    return int(info.value.code), capsys.readouterr().err  # type: ignore[arg-type]


@pytest.mark.slow
@pytest.mark.coil
def test_predict_model_errors(
    coil_model: dict[str, object],
    image_files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = Path(coil_model["dir"])  # type: ignore[arg-type]
    image = str(image_files["1"])
    code, err = _exit(["predict", "--onnx", str(out / "projection.onnx"), image], capsys)
    assert code == 2 and "is a projection" in err and "--recognizer" in err
    code, err = _exit(["predict", "--onnx", str(tmp_path / "none.onnx"), image], capsys)
    assert code == 2 and "does not exist" in err
    (tmp_path / "junk.onnx").write_bytes(b"\x00junk")
    code, err = _exit(["predict", "--onnx", str(tmp_path / "junk.onnx"), image], capsys)
    assert code == 2 and "could not be loaded by onnxruntime" in err
    foreign = tmp_path / "foreign.onnx"
    torch.onnx.export(
        nn.Flatten().eval(), (torch.rand(1, 2, 2),), str(foreign), dynamo=True, opset_version=18
    )
    code, err = _exit(["predict", "--onnx", str(foreign), image], capsys)
    assert code == 2 and "was not exported by torch_eigview" in err


@pytest.mark.slow
@pytest.mark.coil
def test_export_command(
    coil_model: dict[str, object], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = Path(coil_model["dir"]) / "model.pt"  # type: ignore[arg-type]
    assert main(["export", "--model", str(model), "--out", str(tmp_path / "r.onnx"), "--recognizer"]) == 0
    assert "recognizer" in capsys.readouterr().out
    assert read_metadata(tmp_path / "r.onnx").label_names == ("1", "2", "3")
    assert main(["export", "--model", str(model), "--out", str(tmp_path / "p.onnx")]) == 0
    assert read_metadata(tmp_path / "p.onnx").kind == "projection"


def test_export_command_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, err = _exit(
        ["export", "--model", str(tmp_path / "nope.pt"), "--out", str(tmp_path / "x.onnx")], capsys
    )
    assert code == 2 and "does not exist" in err
    (tmp_path / "text.pt").write_text("not a model")
    code, err = _exit(
        ["export", "--model", str(tmp_path / "text.pt"), "--out", str(tmp_path / "x.onnx")], capsys
    )
    assert code == 2 and "could not be read as a torch_eigview model" in err
    torch.save({"format": "torch_eigview.recognizer", "version": 99}, tmp_path / "v99.pt")
    code, err = _exit(
        ["export", "--model", str(tmp_path / "v99.pt"), "--out", str(tmp_path / "x.onnx")], capsys
    )
    assert code == 2 and "format version 99" in err
    code, err = _exit(["export", "--out", str(tmp_path / "x.onnx")], capsys)
    assert code == 2 and "--model" in err
    assert not (tmp_path / "x.onnx").exists()
