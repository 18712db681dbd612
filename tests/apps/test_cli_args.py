"""``eigview`` argument checks: every number finite and named by its flag, bounded work
(views, image side, object ids) refused up front with the limit and how to raise it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import skimage.io

from torch_eigview.apps.cli import main


def _err(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    return capsys.readouterr().err


@pytest.fixture()
def root(tmp_path: Path) -> Path:
    for name in ("obj1__0.png", "obj1__1.png"):
        skimage.io.imsave(tmp_path / name, np.zeros((4, 4), dtype=np.uint8), check_contrast=False)
    return tmp_path


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--alpha", "nan"], "--alpha must be a finite number, got 'nan'"),
        (["--alpha", "5", "--center", "nan"], "--center must be a finite number, got 'nan'"),
        (["--alpha", "5", "--center", "inf"], "--center must be a finite number, got 'inf'"),
        (["--alpha", "5", "--synth", "nan", "20", "1"], "--synth must be a finite number, got 'nan'"),
        (["--alpha", "5", "--test", "-45", "x"], "--test must be a finite number, got 'x'"),
        (["--alpha", "5", "--objects", "1-99999999999"], "EIGVIEW_MAX_OBJECTS"),
    ],
)
def test_coil_arguments(
    root: Path, args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert message in _err(["coil", "--folder", str(root), *args], capsys)


def test_coil_synth_views_bounded(
    root: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    err = _err(["coil", "--folder", str(root), "--alpha", "5", "--synth", "-20", "20", "1e-9"], capsys)
    assert "synth asks for 4e+10 views per object, more than the limit of 3600" in err
    assert "EIGVIEW_MAX_VIEWS" in err
    monkeypatch.setenv("EIGVIEW_MAX_VIEWS", "10")
    assert "limit of 10" in _err(["coil", "--folder", str(root), "--alpha", "5"], capsys)


def test_coil_mixed_pose_unit_is_reported(root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (root / "obj2__0.png").write_bytes((root / "obj1__0.png").read_bytes())
    (root / "obj1__72.png").write_bytes((root / "obj1__0.png").read_bytes())
    assert "mixes pose conventions" in _err(["coil", "--folder", str(root), "--alpha", "5"], capsys)


@pytest.mark.parametrize("command", ["demo"])
def test_image_side_bounded(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    err = _err([command, "--size", "100000"], capsys)
    assert "--size asks for 100000 pixels per image side, more than the limit of 512" in err
    assert "EIGVIEW_MAX_IMAGE_SIDE" in err
    assert "--size=0 must be >= 2" in _err([command, "--size", "0"], capsys)
    assert "--size=1 must be >= 2" in _err([command, "--size", "1"], capsys)  # the flow takes gradients


def test_demo_alpha_named(capsys: pytest.CaptureFixture[str]) -> None:
    assert "--alpha must be a finite number, got 'nan'" in _err(["demo", "--alpha", "nan"], capsys)
    assert "--alpha must be a finite number" in _err(["demo", "--alpha", "inf"], capsys)


@pytest.mark.parametrize("opset", ["99", "17", "x"])
def test_export_opset_checked_before_reading_the_model(
    opset: str, capsys: pytest.CaptureFixture[str]
) -> None:
    err = _err(["export", "--model", "missing.pt", "--out", "o.onnx", "--opset", opset], capsys)
    assert "--opset" in err and "missing.pt" not in err


def test_flow_choices_are_the_flow_methods() -> None:
    """The commands list the flows without importing torch; the list must stay
    geometry.flow.METHODS, with the synthesis default as the default."""
    import argparse

    from torch_eigview.apps.coil_command import add_synthesis_arguments
    from torch_eigview.geometry.flow import METHODS
    from torch_eigview.synthesis import SynthesisOptions

    parser = argparse.ArgumentParser()
    add_synthesis_arguments(parser)
    flow = next(a for a in parser._actions if a.dest == "flow")
    assert flow.choices is not None and set(flow.choices) == set(METHODS)
    assert flow.default == SynthesisOptions().flow
