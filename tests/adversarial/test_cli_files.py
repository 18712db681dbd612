"""Bad files given to ``eigview export`` and ``predict`` (models, ONNX graphs, images) and
outputs that would destroy an input: each must end in exit status 2 (1 for ``predict``'s
per-image failures) and a message naming the file, the constraint and the value, with
every input keeping its bytes. Good files (``GOOD``) must be answered right: an exported
graph and its model file recognize an image alike, an output beside the inputs is written.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
import tifffile

from torch_eigview.io.checkpoint import load_recognizer

from tests.adversarial import files
from tests.adversarial.harness import (
    DAMAGED,
    EMPTY,
    Case,
    Good,
    Ran,
    command,
    intact,
    judge,
    outcome,
    params,
)

A = ("--alpha", "10")


def _nan_tiff(tmp: Path) -> None:
    files.onnx(tmp)
    tifffile.imwrite(tmp / "n.tif", np.full((4, 6), np.nan, dtype=np.float32), photometric="minisblack")


def _with_onnx(*images: tuple[str, tuple[int, ...], str]) -> object:
    def setup(tmp: Path) -> None:
        files.onnx(tmp)
        for name, shape, dtype in images:
            files.image(tmp, name, shape, dtype)

    return setup


def _model_then(make: object) -> object:
    def setup(tmp: Path) -> None:
        make(files.model(tmp))  # type: ignore[operator]

    return setup


EXPORT = [
    Case(
        "model-missing",
        command("export", "--model", "{tmp}/none.pt", "--out", "{tmp}/m.onnx"),
        r"none\.pt'? does not exist",
    ),
    Case(
        "model-text",
        command(
            "export", "--model", "{tmp}/t.pt", "--out", "{tmp}/m.onnx", setup=lambda t: files.text(t / "t.pt")
        ),
        r"t\.pt'? " + DAMAGED,
    ),
    Case(
        "model-truncated",
        command(
            "export", "--model", "{tmp}/model.pt", "--out", "{tmp}/m.onnx", setup=_model_then(files.truncated)
        ),
        r"model\.pt'? " + DAMAGED,
    ),
    Case(
        "model-directory",
        command("export", "--model", "{tmp}", "--out", "{tmp}/m.onnx"),
        r"model (file )?'?/.*'? is (not a file|a directory, not a regular file)",
    ),
    Case(
        "model-plain-dict",
        command(
            "export",
            "--model",
            "{tmp}/d.pt",
            "--out",
            "{tmp}/m.onnx",
            setup=lambda t: files.torch_file(t / "d.pt", {"a": 1}),
        ),
        r"d\.pt'? is not a torch_eigview recognizer \(format",
    ),
    Case(
        "model-pickled-object",
        command(
            "export",
            "--model",
            "{tmp}/o.pt",
            "--out",
            "{tmp}/m.onnx",
            setup=lambda t: files.torch_file(t / "o.pt", Path("x")),
        ),
        r"o\.pt'? " + DAMAGED,
    ),
    Case(
        "opset-17",
        command(
            "export", "--model", "{tmp}/model.pt", "--out", "{tmp}/m.onnx", "--opset", "17", setup=files.model
        ),
        r"--opset=17 must be >= 18",
    ),
    Case(
        "opset-text",
        command(
            "export", "--model", "{tmp}/model.pt", "--out", "{tmp}/m.onnx", "--opset", "x", setup=files.model
        ),
        r"--opset must be an integer, got 'x'",
    ),
    Case(
        "opset-99",
        command(
            "export", "--model", "{tmp}/model.pt", "--out", "{tmp}/m.onnx", "--opset", "99", setup=files.model
        ),
        r"--opset=99 must be at most \d+",
    ),
]

PREDICT = [
    Case(
        "onnx-missing",
        command("predict", "--onnx", "{tmp}/none.onnx", "{tmp}/a.png", setup=lambda t: files.image(t)),
        r"none\.onnx'? does not exist",
    ),
    Case(
        "onnx-text",
        command(
            "predict",
            "--onnx",
            "{tmp}/t.onnx",
            "{tmp}/a.png",
            setup=lambda t: (files.text(t / "t.onnx"), files.image(t)),
        ),
        r"t\.onnx'? could not be loaded .*([Pp]rotobuf parsing failed|INVALID_PROTOBUF)",
    ),
    Case(
        "onnx-truncated",
        command(
            "predict",
            "--onnx",
            "{tmp}/m.onnx",
            "{tmp}/a.png",
            setup=lambda t: (files.truncated(files.onnx(t)), files.image(t)),
        ),
        r"m\.onnx'? could not be loaded .*([Pp]rotobuf parsing failed|INVALID_PROTOBUF)",
    ),
    Case(
        "onnx-directory",
        command("predict", "--onnx", "{tmp}", "{tmp}/a.png", setup=lambda t: files.image(t)),
        r"ONNX model .* is a directory, not a regular file",
    ),
    Case(
        "onnx-fifo",
        command(
            "predict",
            "--onnx",
            "{tmp}/f.onnx",
            "{tmp}/a.png",
            setup=lambda t: (files.fifo(t / "f.onnx"), files.image(t)),
        ),
        r"ONNX model .*f\.onnx is a FIFO .*not a regular file",
    ),
    Case(
        "image-missing",
        command("predict", "--onnx", "{tmp}/m.onnx", "{tmp}/none.png", setup=files.onnx),
        r"none\.png does not exist",
    ),
    Case(
        "image-directory",
        command(
            "predict",
            "--onnx",
            "{tmp}/m.onnx",
            "{tmp}/d.png",
            setup=lambda t: (files.onnx(t), os.mkdir(t / "d.png")),
        ),
        r"d\.png is a directory, not a regular file",
    ),
    Case(
        "image-empty-file",
        command(
            "predict",
            "--onnx",
            "{tmp}/m.onnx",
            "{tmp}/e.png",
            setup=lambda t: (files.onnx(t), (t / "e.png").write_bytes(b"")),
        ),
        r"e\.png.*" + EMPTY,
    ),
    Case(
        "image-wrong-size",
        command(
            "predict", "--onnx", "{tmp}/m.onnx", "{tmp}/b.png", setup=_with_onnx(("b.png", (5, 5), "uint8"))
        ),
        r"b\.png has shape \(C, H, W\)=\(1, 5, 5\), but the model expects \(1, 4, 6\)",
    ),
    Case(
        "image-rgb-for-grey",
        command(
            "predict",
            "--onnx",
            "{tmp}/m.onnx",
            "{tmp}/c.png",
            setup=_with_onnx(("c.png", (4, 6, 3), "uint8")),
        ),
        r"c\.png has shape \(C, H, W\)=\(3, 4, 6\), but the model expects \(1, 4, 6\)",
    ),
    Case(
        "image-nan-tiff",
        command("predict", "--onnx", "{tmp}/m.onnx", "{tmp}/n.tif", setup=_nan_tiff),
        r"n\.tif must be finite, got NaN",
    ),
    Case(
        "image-fifo",
        command(
            "predict",
            "--onnx",
            "{tmp}/m.onnx",
            "{tmp}/f.png",
            setup=lambda t: (files.onnx(t), files.fifo(t / "f.png")),
        ),
        r"f\.png is a FIFO .*not a regular file",
    ),
]


def _two_files(tmp: Path) -> None:
    files.text(tmp / "r.json", "[]\n")


# An output that names an input, or two outputs one file: refused, and the input keeps its bytes.
LOST = [
    Case(
        "coil-save-over-an-image",
        intact(
            command("coil", "--folder", "{tmp}", *A, "--save", "{tmp}/obj1__0.png", setup=files.coil),
            "obj1__0.png",
        ),
        r"--save=.*obj1__0\.png'? is the same file as an image of --folder",
    ),
    Case(
        "coil-json-over-an-image",
        intact(
            command("coil", "--folder", "{tmp}", *A, "--json", "{tmp}/obj2__5.png", setup=files.coil),
            "obj2__5.png",
        ),
        r"--json=.*obj2__5\.png'? is the same file as an image of --folder",
    ),
    Case(
        "predict-json-over-the-model",
        intact(
            command(
                "predict",
                "--onnx",
                "{tmp}/m.onnx",
                "{tmp}/a.png",
                "--json",
                "{tmp}/m.onnx",
                setup=lambda t: (files.onnx(t), files.image(t)),
            ),
            "m.onnx",
        ),
        r"--json=.*m\.onnx'? is the same file as --onnx",
    ),
    Case(
        "export-out-over-a-hardlink-of-the-model",
        intact(
            command(
                "export",
                "--model",
                "{tmp}/model.pt",
                "--out",
                "{tmp}/hard.onnx",
                setup=lambda t: os.link(files.model(t), t / "hard.onnx"),
            ),
            "model.pt",
        ),
        r"--out=.*hard\.onnx'? is the same file as --model",
    ),
    Case(
        "demo-png-and-json-one-file",
        intact(
            command("demo", "--png", "{tmp}/r.json", "--json", "{tmp}/r.json", setup=_two_files), "r.json"
        ),
        r"--json=.*r\.json'? and --png=.*r\.json'? name the same file",
    ),
]
CASES = EXPORT + PREDICT + LOST

#: The model's labels and poses (:func:`tests.io.test_checkpoint.make_recognizer`).
LABELS = {"cup", "duck", "car"}
POSES = {5.0 * i for i in range(18)}


def _two_images(tmp: Path) -> None:
    files.onnx(tmp)
    files.model(tmp)
    files.image(tmp, "a.png")
    files.image(tmp, "b.tif", dtype="float32")


def _predictions(out: Ran, tmp: Path) -> bool:
    """r.json: one known label, gallery pose and finite distance per image, in order."""
    rows = json.loads((tmp / "r.json").read_text())
    assert [r["image"] for r in rows] == [str(tmp / "a.png"), str(tmp / "b.tif")], rows
    for r in rows:
        assert r["label"] in LABELS and r["pose"] in POSES, r
        assert math.isfinite(r["distance"]) and r["distance"] >= 0, r
    return True


def _onnx_and_model(tmp: Path) -> tuple[object, object]:
    """``predict`` of the same images with the exported graph and with its model file."""
    _two_images(tmp)
    images = ("{tmp}/a.png", "{tmp}/b.tif")
    return (
        command("predict", "--onnx", "{tmp}/m.onnx", *images)(tmp),
        command("predict", "--model", "{tmp}/model.pt", *images)(tmp),
    )


def _agree(out: tuple[Ran, Ran], tmp: Path) -> bool:
    """The two answers: the same label and pose per image, distances equal to float32."""
    onnx, model = ([line.split("\t") for line in o.stdout.splitlines()] for o in out)
    assert len(onnx) == len(model) == 2, out
    for a, b in zip(onnx, model, strict=True):
        assert a[:3] == b[:3], (a, b)
        assert math.isclose(float(a[3].split()[1]), float(b[3].split()[1]), rel_tol=1e-4), (a, b)
    return True


def _saved(out: Ran, tmp: Path) -> bool:
    """``coil --save`` beside the images: a recognizer of both objects."""
    recognizer, _ = load_recognizer(tmp / "model.pt")
    assert set(recognizer.labels.tolist()) == {1, 2}, recognizer.labels
    return True


GOOD = [
    Good(
        "predict-onnx",
        command(
            "predict",
            "--onnx",
            "{tmp}/m.onnx",
            "{tmp}/a.png",
            "{tmp}/b.tif",
            "--json",
            "{tmp}/r.json",
            setup=_two_images,
        ),
        _predictions,
    ),
    Good("predict-onnx-and-model-agree", _onnx_and_model, _agree),
    Good(
        "coil-save-beside-the-images",
        command(
            "coil", "--folder", "{tmp}", *A, "--threads", "1", "--save", "{tmp}/model.pt", setup=files.coil
        ),
        _saved,
    ),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_file_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what


@pytest.mark.parametrize("case", params(GOOD))
def test_good_file_is_answered_right(case: Good, tmp_path: Path) -> None:
    kind, what = judge(case, tmp_path)
    assert kind == "right", what
