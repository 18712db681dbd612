"""The camera-model script (``examples/paper/camera_models.py``): a small run and its record,
and each bad argument ending in exit status 2 with one line naming the flag and the value."""

from __future__ import annotations

import json
import re
from pathlib import Path

import camera_models
import pytest


def test_small_run_writes_its_record(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    argv = ["--cameras", "orthographic", "perspective", "--alpha", "10", "--views", "2", "--size", "24"]
    outs = camera_models.main([*argv, "--shapes", "egg,head", "--record", str(out)])
    assert set(outs) == {"orthographic", "perspective"}
    record = json.loads(out.read_text())
    accuracy, _, errors = record["tables"]
    assert accuracy["columns"] == ["α", "N", "orthographic", "perspective", "paper"]
    assert accuracy["rows"][0][:2] == [10.0, 2] and accuracy["rows"][0][-1] == 100.0  # the paper's
    assert [row[0] for row in errors["rows"]] == ["orthographic", "perspective"]
    assert record["command"] == "python examples/paper/camera_models.py " + " ".join(
        [*argv, "--shapes", "egg,head", "--record", str(out)]
    )
    assert record["results"]["perspective"]["results"][0]["n_test"] == 2 * 90


def test_textured_backdrop_with_estimated_masks(tmp_path: Path) -> None:
    argv = [
        "--cameras",
        "orthographic",
        "--alpha",
        "10",
        "--views",
        "2",
        "--size",
        "24",
        "--shapes",
        "egg,head",
    ]
    outs = camera_models.main([*argv, "--background", "textured", "--masks", "estimated", "--record", ""])
    run = outs["orthographic"]
    assert run["background"] == "textured" and run["masks"] == "estimated"
    assert run["results"][0]["n_test"] == 2 * 90  # type: ignore[index]


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--shapes", "cube"], r"--shapes has unknown shape\(s\) \['cube'\]"),
        (["--shapes", ""], r"--shapes.*''"),
        (["--alpha", "0"], r"--alpha=0.0 must not be a multiple of 180 degrees"),
        (["--alpha", "nan"], r"--alpha must be a finite number, got 'nan'"),
        (["--size", "1"], r"--size=1 must be >= 2"),
        (
            ["--size", "3"],
            r"rendered at \(3, 3\) pixels give too few distinct views for 15.*--size.*--shapes",
        ),
        (["--views", "4"], r"--views.*invalid choice: 4"),
        (["--cameras", "fisheye"], r"invalid choice: 'fisheye'"),
        (["--background", "textured", "--masks", "drawn"], r"--masks.*invalid choice: 'drawn'"),
        (["--background", "white"], r"--background.*invalid choice: 'white'"),
        (["--masks", "estimated"], r"--masks estimated goes with --background textured"),
        (
            ["--record", "/nonexistent-folder/r.json"],
            r"--record=.*the folder '/nonexistent-folder' does not exist",
        ),
    ],
)
def test_bad_argument_is_one_line(argv: list[str], match: str, capsys: pytest.CaptureFixture[str]) -> None:
    small = ["--cameras", "orthographic", "--alpha", "10", "--views", "2", "--record", ""]
    with pytest.raises(SystemExit) as info:
        camera_models.main([*small, *argv])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "Traceback" not in err
    assert re.search(match, err.strip().splitlines()[-1]), err
