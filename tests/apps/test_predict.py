"""``eigview predict`` against damaged models and hostile inputs: the graph checked before it
runs, special files refused unopened, damaged rows reported per row, names escaped."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import onnx
import pytest
import skimage.io
import torch
from onnx import helper, numpy_helper

from torch_eigview.apps.cli import main
from torch_eigview.apps.prediction import escape
from torch_eigview.decomposition import Eigenspace
from torch_eigview.io.checkpoint import save_recognizer
from torch_eigview.io.onnx import export_recognizer
from torch_eigview.io.onnx_check import check_recognizer_graph
from torch_eigview.io.onnx_checksum import DIGEST_KEY, append_checksum
from torch_eigview.io.onnx_metadata import OnnxModelInfo, graph_doc_string
from torch_eigview.nn.recognition import NearestNeighborRecognizer

from tests.helpers import rand, run_cli

SHAPE = (1, 8, 8)


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recognizer of 3 labels over 9 random 8x8 views, exported."""
    views = rand(9, *SHAPE, dtype=torch.float32)
    projection = Eigenspace(3).fit(views).to_module()
    labels = torch.arange(9) % 3
    rec = NearestNeighborRecognizer.from_views(projection, views, labels, torch.arange(9.0), ["a", "b", "c"])
    path = tmp_path_factory.mktemp("model") / "rec.onnx"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        export_recognizer(rec, path)
    return path


@pytest.fixture(scope="module")
def images(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    out = tmp_path_factory.mktemp("images")
    rng = np.random.default_rng(0)
    paths = []
    for i in range(3):
        path = out / f"img{i}.png"
        skimage.io.imsave(path, rng.integers(0, 256, SHAPE[1:], dtype=np.uint8), check_contrast=False)
        paths.append(str(path))
    return paths


def _rewrite(src: Path, dst: Path, edit: object) -> Path:
    """A crafted model: ``src`` edited, with a valid checksum and the graph's copy of the
    metadata rewritten to match (what an attacker who re-signs the file, or a bug in an
    exporter, would hand to predict; tests/io/test_model_content.py edits the metadata alone)."""
    m = onnx.load(str(src))
    kept = [p for p in m.metadata_props if p.key != DIGEST_KEY]
    del m.metadata_props[:]
    m.metadata_props.extend(kept)
    edit(m)  # type: ignore[operator]
    m.graph.doc_string = graph_doc_string({p.key: p.value for p in m.metadata_props})
    onnx.save(m, str(dst))
    append_checksum(dst)
    return dst


def _set_meta(m: onnx.ModelProto, key: str, value: str) -> None:
    for p in m.metadata_props:
        if p.key == key:
            p.value = value


def test_escape() -> None:
    assert escape("obj\x1b[31m\nFAKE\tx\u2028") == "obj\\x1b[31m\\nFAKE\\tx\\u2028"
    assert escape("plain name 7") == "plain name 7"


def test_label_names_printed_escaped(
    model: Path, images: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    names = json.dumps(["\x1b[2J", "b\nimg9.png\tlabel x", "c\x1b[31m\r"])
    bad = _rewrite(model, tmp_path / "m.onnx", lambda m: _set_meta(m, "label_names", names))
    code, out, _ = run_cli(["predict", "--onnx", str(bad), *images], capsys)
    assert code == 0
    assert "\x1b" not in out and "\r" not in out and len(out.splitlines()) == len(images)
    assert any(
        t in out for t in ("label \\x1b[2J\t", "label b\\nimg9.png\\tlabel x\t", "label c\\x1b[31m\\r\t")
    )


def test_wrong_label_list_length_is_refused(
    model: Path, images: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = _rewrite(model, tmp_path / "m.onnx", lambda m: _set_meta(m, "label_names", json.dumps(["a"])))
    code, _, err = run_cli(
        ["predict", "--onnx", str(bad), *images, "--json", str(tmp_path / "p.json")], capsys
    )
    assert code == 2
    assert "'label_names' must name every label index of the graph" in err and "got 1 names" in err
    assert not (tmp_path / "p.json").exists()


def _poison_codes(m: onnx.ModelProto) -> None:
    for t in m.graph.initializer:
        if "codes" in t.name:
            arr = numpy_helper.to_array(t).copy()
            arr.flat[0] = np.nan
            t.CopyFrom(numpy_helper.from_array(arr, t.name))
            return
    raise AssertionError("no codes initializer")


def test_tampered_codes_refused_before_running(
    model: Path, images: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = _rewrite(model, tmp_path / "m.onnx", _poison_codes)
    code, out, err = run_cli(["predict", "--onnx", str(bad), *images], capsys)
    assert code == 2 and out == ""
    assert "codes" in err and "NaN or infinite" in err


def _add_expand(m: onnx.ModelProto) -> None:
    shape = numpy_helper.from_array(np.array([1 << 20, 1 << 20], dtype=np.int64), "huge_shape")
    m.graph.initializer.append(shape)
    m.graph.node.append(helper.make_node("Expand", ["distance", "huge_shape"], ["blown"]))


def test_foreign_operator_refused(model: Path, tmp_path: Path) -> None:
    bad = _rewrite(model, tmp_path / "m.onnx", _add_expand)
    info = OnnxModelInfo.from_props({p.key: p.value for p in onnx.load(str(model)).metadata_props})
    with pytest.raises(
        ValueError, match=r"operators a torch_eigview recognizer never has: \['ai.onnx:Expand'\]"
    ):
        check_recognizer_graph(bad, info)
    check_recognizer_graph(model, info)  # the real export passes


def test_wrong_input_shape_refused(model: Path, tmp_path: Path) -> None:
    info = OnnxModelInfo.from_props({p.key: p.value for p in onnx.load(str(model)).metadata_props})
    other = OnnxModelInfo(info.kind, (1, 8, 9), info.n_components, info.unit_norm, info.label_names)
    with pytest.raises(ValueError, match=r"must have one input 'images' \(B, 1, 8, 9\)"):
        check_recognizer_graph(model, other)


def test_weight_budget(model: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The byte budget is the max_model_bytes limit; the command reads it from the environment."""
    from torch_eigview.apps.cli import limits_from_environment
    from torch_eigview.config import config_context

    info = OnnxModelInfo.from_props({p.key: p.value for p in onnx.load(str(model)).metadata_props})
    with config_context(max_model_bytes=64), pytest.raises(ValueError, match="max_model_bytes"):
        check_recognizer_graph(model, info)
    check_recognizer_graph(model, info)  # the default budget again
    assert limits_from_environment({"EIGVIEW_MAX_MODEL_BYTES": "64"}) == {"max_model_bytes": 64}
    with pytest.raises(ValueError, match=r"EIGVIEW_MAX_MODEL_BYTES='lots' must be a positive integer"):
        limits_from_environment({"EIGVIEW_MAX_MODEL_BYTES": "lots"})
    monkeypatch.setenv("EIGVIEW_MAX_MODEL_BYTES", "1_0")  # int() would take it as 10
    with pytest.raises(SystemExit) as exited:
        main(["predict", "--onnx", str(model), "x.png"])
    assert exited.value.code == 2


def test_fifo_model_and_fifo_image_never_opened(model: Path, images: list[str], tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    fifo_model = tmp_path / "pipe.onnx"
    os.mkfifo(fifo_model)
    argv = [
        sys.executable,
        "-m",
        "torch_eigview.apps.predict",
        "--onnx",
        str(model),
        images[0],
        str(fifo),
        images[1],
    ]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1, proc.stderr
    assert "pipe.png is a FIFO (named pipe), not a regular file" in proc.stderr
    assert len(proc.stdout.splitlines()) == 2
    argv = [sys.executable, "-m", "torch_eigview.apps.predict", "--onnx", str(fifo_model), images[0]]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "pipe.onnx is a FIFO" in proc.stderr


def test_float_tiff_outside_range_is_an_error(
    model: Path, images: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import tifffile

    big = tmp_path / "big.tif"
    tifffile.imwrite(big, np.full(SHAPE[1:], 1e32, dtype=np.float32))
    code, out, err = run_cli(["predict", "--onnx", str(model), images[0], str(big)], capsys)
    assert code == 1 and "values outside [0, 1]" in err and len(out.splitlines()) == 1


def test_many_images_in_batches(model: Path, images: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    many = images * 50  # 150 paths: three batches of up to 64
    code, out, _ = run_cli(["predict", "--onnx", str(model), *many], capsys)
    lines = out.splitlines()
    assert code == 0 and len(lines) == len(many)
    assert lines[:3] == lines[3:6] == lines[-3:]


def test_reject_prints_unknown(
    model: Path, images: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A recognizer with rejection thresholds: its gallery images are known, an image far
    from every gallery view is "unknown"; a model without a ``known`` output is refused."""
    gallery = rand(4, *SHAPE, dtype=torch.float32)
    projection = Eigenspace(3).fit(gallery).to_module()
    rec = NearestNeighborRecognizer.from_views(
        projection, gallery, torch.arange(4) % 2, torch.zeros(4), ["a", "b"]
    )
    # A quarter of the closest two gallery views' distance: the 8-bit files stay well inside it.
    gap = float(torch.pdist(rec.codes).min())
    rec.set_rejection(torch.tensor([float("inf"), gap / 4]))
    stranger = 1.0 - gallery[:1]  # the negative of a gallery view
    files = []
    for i, view in enumerate([*gallery[:2], stranger[0]]):
        files.append(str(tmp_path / f"v{i}.png"))
        skimage.io.imsave(files[-1], (view[0].numpy() * 255).round().astype(np.uint8), check_contrast=False)
    read = torch.stack([torch.from_numpy(skimage.io.imread(f)).float()[None] / 255 for f in files])
    assert rec.predict(read, reject=True).known.tolist() == [True, True, False]  # type: ignore[union-attr]
    path = tmp_path / "reject.onnx"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert export_recognizer(rec, path).reject
    capsys.readouterr()  # the exporter's progress lines
    save_recognizer(rec, tmp_path / "reject.pt")
    for flag, source in (("--onnx", path), ("--model", tmp_path / "reject.pt")):
        argv = ["predict", flag, str(source), "--reject", *files, "--json", str(tmp_path / "p.json")]
        code, out, _ = run_cli(argv, capsys)
        assert code == 0
        lines = out.splitlines()
        assert "\tlabel a\t" in lines[0] and "\tlabel b\t" in lines[1] and "\tunknown\t" in lines[2]
        assert [r["known"] for r in json.loads((tmp_path / "p.json").read_text())] == [True, True, False]
    code, out, err = run_cli(["predict", "--onnx", str(model), "--reject", *images], capsys)
    assert code == 2 and not out
    assert "--reject needs a model with rejection thresholds" in err and str(model) in err
