"""Bad files given to ``eigview export`` and ``predict`` (models, ONNX graphs, images) and
outputs that would destroy an input: each must end in exit status 2 (1 for ``predict``'s
per-image failures) and a message naming the file, the constraint and the value, with
every input keeping its bytes.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import tifffile

from tests.adversarial import files
from tests.adversarial.harness import Case, command, intact, outcome

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
        r"none\.pt.*(does not exist|no such)",
    ),
    Case(
        "model-text",
        command(
            "export", "--model", "{tmp}/t.pt", "--out", "{tmp}/m.onnx", setup=lambda t: files.text(t / "t.pt")
        ),
        r"t\.pt",
    ),
    Case(
        "model-truncated",
        command(
            "export", "--model", "{tmp}/model.pt", "--out", "{tmp}/m.onnx", setup=_model_then(files.truncated)
        ),
        r"model\.pt",
    ),
    Case(
        "model-directory",
        command("export", "--model", "{tmp}", "--out", "{tmp}/m.onnx"),
        r"model file '.*' is not a file",
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
        r"d\.pt.*(format|not)",
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
        r"o\.pt",
    ),
    Case(
        "opset-17",
        command(
            "export", "--model", "{tmp}/model.pt", "--out", "{tmp}/m.onnx", "--opset", "17", setup=files.model
        ),
        r"--opset.*17.*18",
    ),
    Case(
        "opset-text",
        command(
            "export", "--model", "{tmp}/model.pt", "--out", "{tmp}/m.onnx", "--opset", "x", setup=files.model
        ),
        r"--opset.*'x'",
    ),
    Case(
        "opset-99",
        command(
            "export", "--model", "{tmp}/model.pt", "--out", "{tmp}/m.onnx", "--opset", "99", setup=files.model
        ),
        r"--opset.*99",
    ),
]

PREDICT = [
    Case(
        "onnx-missing",
        command("predict", "--onnx", "{tmp}/none.onnx", "{tmp}/a.png", setup=lambda t: files.image(t)),
        r"none\.onnx",
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
        r"t\.onnx",
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
        r"m\.onnx",
    ),
    Case(
        "onnx-directory",
        command("predict", "--onnx", "{tmp}", "{tmp}/a.png", setup=lambda t: files.image(t)),
        r"--onnx.*directory|directory",
    ),
    Case(
        "image-missing",
        command("predict", "--onnx", "{tmp}/m.onnx", "{tmp}/none.png", setup=files.onnx),
        r"none\.png.*(does not exist|no such)",
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
        r"d\.png.*directory",
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
        r"e\.png",
    ),
    Case(
        "image-wrong-size",
        command(
            "predict", "--onnx", "{tmp}/m.onnx", "{tmp}/b.png", setup=_with_onnx(("b.png", (5, 5), "uint8"))
        ),
        r"b\.png.*5.*5.*4.*6|b\.png.*\(1, 4, 6\)",
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
        r"c\.png.*(3|channel)",
    ),
    Case(
        "image-nan-tiff",
        command("predict", "--onnx", "{tmp}/m.onnx", "{tmp}/n.tif", setup=_nan_tiff),
        r"n\.tif.*(NaN|nan|finite)",
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
        r"f\.png.*(FIFO|special|not a regular)",
    ),
]


def _two_files(tmp: Path) -> None:
    files.text(tmp / "r.json", "[]\n")


# An output that names an input, or two outputs one file: refused, and the input keeps its bytes.
LOST = [
    Case(
        "coil-save-over-an-image",
        intact(
            command("coil", "--root", "{tmp}", *A, "--save", "{tmp}/obj1__0.png", setup=files.coil),
            "obj1__0.png",
        ),
        r"--save.*obj1__0\.png.*(input|same file)",
    ),
    Case(
        "coil-json-over-an-image",
        intact(
            command("coil", "--root", "{tmp}", *A, "--json", "{tmp}/obj2__5.png", setup=files.coil),
            "obj2__5.png",
        ),
        r"--json.*obj2__5\.png.*(input|same file)",
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
        r"--json.*m\.onnx.*same file as --onnx",
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
        r"--out.*hard\.onnx.*same file as --model",
    ),
    Case(
        "demo-png-and-json-one-file",
        intact(
            command("demo", "--png", "{tmp}/r.json", "--json", "{tmp}/r.json", setup=_two_files), "r.json"
        ),
        r"r\.json.*(same file|both)",
    ),
]
CASES = EXPORT + PREDICT + LOST


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_file_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what
