"""The README's onnxruntime snippet: at most 15 lines, onnxruntime, numpy and Pillow only, and
with torch blocked it gives ``eigview predict --model``'s answers on a model from ``eigview
fit``, exported by ``eigview export --recognizer``."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import skimage.io

from torch_eigview.apps.cli import main
from torch_eigview.datasets import OrthographicCamera, make_object, render_views

pytest.importorskip("onnxruntime")

README = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
SIDE = 32
AZIMUTHS = list(range(-40, 41, 10))
NAMES = ("egg", "head")
# Importing torch fails in the subprocess: the snippet must not need it.
NO_TORCH = """
import json, sys
sys.modules["torch"] = None
snippet, onnx_path, images = sys.argv[1], sys.argv[2], sys.argv[3:]
for image in images:
    source = snippet.replace('"recognizer.onnx"', repr(onnx_path)).replace('"photos/egg/020.png"', repr(image))
    exec(compile(source, "README snippet", "exec"), {"__name__": "__snippet__"})
assert "torch" not in sys.modules or sys.modules["torch"] is None
"""


def _snippet() -> str:
    blocks = re.findall(r"^```python\n(.*?)^```$", README, flags=re.MULTILINE | re.DOTALL)
    found = [b for b in blocks if "import onnxruntime" in b]
    assert len(found) == 1, "the README should hold one onnxruntime snippet"
    return found[0]


def test_snippet_is_short_and_imports_no_torch() -> None:
    snippet = _snippet()
    assert len(snippet.splitlines()) <= 15
    imported = set()
    for node in ast.walk(ast.parse(snippet)):
        if isinstance(node, ast.Import):
            imported |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add((node.module or "").split(".")[0])
    assert imported == {"json", "numpy", "onnxruntime", "PIL"}
    for name in ('"images"', '"label_index"', '"pose"', '"distance"', '"preprocessing"', '"label_names"'):
        assert name in snippet


@pytest.fixture(scope="module")
def views(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two rendered objects every 10 degrees as RGB PNGs (tinted, so that the gray conversion
    matters), listed in views.csv."""
    root = tmp_path_factory.mktemp("snippet")
    rows = ["path,object,azimuth"]
    tint = np.array([1.0, 0.8, 0.5])
    for name in NAMES:
        images = render_views(make_object(name, seed=1), AZIMUTHS, OrthographicCamera(SIDE))
        (root / name).mkdir()
        for az, image in zip(AZIMUTHS, images, strict=True):
            rgb = image[0].clamp(0, 1).numpy()[..., None] * tint
            skimage.io.imsave(
                root / name / f"{az % 360}.png", (rgb * 255).round().astype(np.uint8), check_contrast=False
            )
            rows.append(f"{name}/{az % 360}.png,{name},{az}")
    (root / "views.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    return root / "views.csv"


@pytest.mark.slow
@pytest.mark.parametrize("channels", ["1", "3"])
def test_snippet_without_torch_answers_as_predict_model(
    views: Path, tmp_path: Path, channels: str, capsys: pytest.CaptureFixture[str]
) -> None:
    model, onnx_path = tmp_path / "model.pt", tmp_path / "recognizer.onnx"
    fit = ["fit", "--manifest", str(views), "--seeds", "0", "10", "--synth", "-20", "20", "2", "-k", "8"]
    # 24 x 24 from 32 x 32 files: the snippet resizes, and converts RGB to the model's channels.
    assert main([*fit, "--size", "24", "24", "--channels", channels, "--quiet", "--out", str(model)]) == 0
    assert main(["export", "--model", str(model), "--out", str(onnx_path), "--recognizer"]) == 0
    images = [str(views.parent / name / f"{az % 360}.png") for name in NAMES for az in (-40, -15, 20, 30)]
    images = [p for p in images if Path(p).exists()]
    capsys.readouterr()
    assert main(["predict", "--model", str(model), *images]) == 0
    want = [line.split("\t") for line in capsys.readouterr().out.splitlines()]

    proc = subprocess.run(
        [sys.executable, "-c", NO_TORCH, _snippet(), str(onnx_path), *images],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    got = [line.split() for line in proc.stdout.splitlines()]
    assert len(got) == len(want) == len(images)
    assert [g[0] for g in got] == [w[1].removeprefix("label ") for w in want]
    assert [float(g[1]) for g in got] == pytest.approx([float(w[2].split()[1]) for w in want], abs=1e-4)
    assert [float(g[2]) for g in got] == pytest.approx(
        [float(w[3].split()[1]) for w in want], rel=1e-4, abs=1e-5
    )
