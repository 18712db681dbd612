"""Bad input to ``eigview evaluate``, ``predict --model`` (and ``--onnx`` of a fit model)
and ``coil --seeds M --overlap`` / ``--extent``: each must
end in exit status 2 (1 for ``predict``'s per-image failures) and a message that names the
flag or file, the constraint and the value, with every input keeping its bytes.

The model is :func:`tests.adversarial.views.model` (one fit, copied); a tampered model is
that model re-saved with one field changed, so its checksum is valid and only the
validation of its contents can catch it. Good runs (``GOOD``) must be answered right: the
model recognizes the views it was fitted on, with its file and with its exported graph.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tifffile
import torch

from torch_eigview.apps.cli import main
from torch_eigview.io.checkpoint import load_recognizer, payload_digest, save_recognizer

from tests.adversarial import files, views
from tests.adversarial.harness import Case, Good, Ran, command, intact, judge, outcome, params

MODEL = ("--model", "{tmp}/model.pt")
VIEWS = ("--manifest", "{tmp}/views.csv")


def _evaluate(id: str, *flags: str, match: str, setup: object = views.model, todo: str = "") -> Case:
    return Case(id, command("evaluate", *flags, "--quiet", setup=setup), match, todo=todo)  # type: ignore[arg-type]


def _tampered(**change: Any) -> object:
    """The model re-saved with ``change``: ``preprocessing`` fields into its record, or
    ``reject_thresholds`` into the recognizer (checksum recomputed by the writer)."""

    def setup(tmp: Path) -> None:
        path = views.model(tmp)
        recognizer, meta = load_recognizer(path)
        thresholds = change.pop("reject_thresholds", None)
        if "preprocessing" in change:
            meta["preprocessing"] = change["preprocessing"]
        else:
            meta["preprocessing"] = {**meta["preprocessing"], **change}
        save_recognizer(recognizer, path, meta)
        if thresholds is not None:  # past set_rejection's and save_recognizer's checks, as a foreign writer
            payload = torch.load(path, weights_only=True)
            payload["reject_thresholds"] = torch.tensor(thresholds, dtype=payload["codes"].dtype)
            payload["sha256"] = payload_digest(payload)
            torch.save(payload, path)

    return setup


def _without_rejection(tmp: Path) -> None:
    path = views.model(tmp)
    recognizer, meta = load_recognizer(path)
    recognizer.set_rejection(None)
    save_recognizer(recognizer, path, meta)


def _with(make: object, name: str) -> object:
    """The model, and ``name`` made by ``make(path)``."""

    def setup(tmp: Path) -> None:
        views.model(tmp)
        make(tmp / name)  # type: ignore[operator]

    return setup


def _nan_tiff(path: Path) -> None:
    tifffile.imwrite(path, np.full((32, 32), np.nan, dtype=np.float32), photometric="minisblack")


def _seeds_only(tmp: Path) -> None:
    views.model(tmp)
    lines = (tmp / "views.csv").read_text().splitlines()
    (tmp / "views.csv").write_text("\n".join(line for line in lines if not line.endswith(",20")) + "\n")


PREP = [
    ("size-0", {"size": [0, 32]}, r"size must be \(H, W\) with ints >= 1, got \(0, 32\)"),
    ("size-text", {"size": ["a", 32]}, r"size must be \(H, W\) with ints >= 1, got \('a', 32\)"),
    ("size-float", {"size": [32.0, 32]}, r"size must be \(H, W\) with ints >= 1, got \(32\.0, 32\)"),
    (
        "size-other",
        {"size": [16, 16]},
        r"preprocessing gives \(1, 16, 16\), its eigenspace takes \(1, 32, 32\)",
    ),
    ("channels-2", {"channels": 2}, r"channels must be 1 or 3, got 2"),
    ("background-magic", {"background": "magic"}, r"background must be one of .*, got 'magic'"),
    (
        "colour-out-of-range",
        {"background": "colour", "colour": [2.0]},
        r"colour must be 1 or 3 values in \[0, 1\]",
    ),
    (
        "tolerance-text",
        {"background": "auto", "tolerance": "0.1"},
        r"tolerance must be a positive number, got '0\.1'",
    ),
    (
        "tolerance-negative",
        {"background": "auto", "tolerance": -1.0},
        r"tolerance must be a positive number, got -1",
    ),
    ("unit-norm-text", {"unit_norm": "yes"}, r"unit_norm must be a bool, got 'yes'"),
    ("resize-other", {"resize": "nearest"}, r"resize must be .*, got 'nearest'"),
    ("record-not-a-mapping", {"preprocessing": "x"}, r"damaged preprocessing record: 'x' is not a mapping"),
    (
        "record-missing-field",
        {"preprocessing": {"size": [32, 32]}},
        r"damaged preprocessing record: (.*missing.*'channels'|'channels'.*missing)",
    ),
]
#: The PREP cases whose message does not say the cause yet: what it should say.

#: Tampered rejection thresholds (t_dffs, t_difs): (case id, values, what the error shows).
THRESHOLDS = [
    ("nan", [math.nan, math.nan], r"got \[nan, nan\]"),
    ("negative", [-1.0, -1.0], r"got \[-1\.0, -1\.0\]"),
    ("zero", [0.0, 0.0], r"got \[0\.0, 0\.0\]"),
]

EVALUATE = [
    _evaluate("model-missing", "--model", "{tmp}/none.pt", *VIEWS, match=r"none\.pt'? does not exist"),
    _evaluate(
        "model-is-the-manifest",
        "--model",
        "{tmp}/views.csv",
        *VIEWS,
        match=r"views\.csv'? could not be read as a torch_eigview model \((damaged|truncated)",
    ),
    _evaluate(
        "model-directory",
        "--model",
        "{tmp}/egg",
        *VIEWS,
        match=r"model (file )?'?.*egg'? is (not a file|a directory, not a regular file)",
    ),
    _evaluate(
        "model-fifo",
        "--model",
        "{tmp}/f.pt",
        *VIEWS,
        setup=_with(files.fifo, "f.pt"),
        match=r"model (file )?'?.*f\.pt'? is (not a file|a FIFO .*not a regular file)",
    ),
    *(
        _evaluate(
            f"prep-{id}",
            *MODEL,
            *VIEWS,
            setup=_tampered(**change),
            match=r"model\.pt.*" + match,
        )
        for id, change, match in PREP
    ),
    *(
        _evaluate(
            f"reject-thresholds-{id}",
            *MODEL,
            *VIEWS,
            "--reject",
            setup=_tampered(reject_thresholds=values),
            match=r"model\.pt'?: entry 'reject_thresholds' must be .*> 0.*" + match,
        )
        for id, values, match in THRESHOLDS
    ),
    _evaluate(
        "reject-without-thresholds",
        *MODEL,
        *VIEWS,
        "--reject",
        setup=_without_rejection,
        match=r"--reject needs a model with calibrated rejection .*model\.pt has none",
    ),
    _evaluate("pose-bogus", *MODEL, *VIEWS, "--pose", "mean", match=r"--pose: invalid choice: 'mean'"),
    _evaluate(
        "exclude-seeds-leaves-nothing",
        *MODEL,
        *VIEWS,
        "--exclude-seeds",
        setup=_seeds_only,
        match=r"--exclude-seeds leaves no view of .*views\.csv: every view lies at a seed azimuth \(0, 10 degrees\)",
    ),
    _evaluate(
        "every-row-bad",
        *MODEL,
        *VIEWS,
        setup=lambda t: (
            views.model(t),
            (t / "views.csv").write_text("path,object,azimuth\nnone.png,egg,0\n"),
        ),
        match=r"views\.csv lists no view, only bad lines: .*views\.csv line 2: image .*none\.png does not exist",
    ),
    _evaluate(
        "pattern-without-root",
        *MODEL,
        "--pattern",
        "{{object}}/{{azimuth}}.png",
        match=r"--pattern .* needs --root",
    ),
    _evaluate(
        "json-directory", *MODEL, *VIEWS, "--json", "{tmp}/egg", match=r"--json='.*egg' is a directory"
    ),
    _evaluate(
        "json-dev-full",
        *MODEL,
        *VIEWS,
        "--json",
        "/dev/full",
        match=r"--json='/dev/full' is a character device",
    ),
    _evaluate(
        "json-missing-folder",
        *MODEL,
        *VIEWS,
        "--json",
        "{tmp}/no/r.json",
        match=r"--json=.*the folder .*no' does not exist",
    ),
    Case(
        "json-is-the-model",
        intact(
            command("evaluate", *MODEL, *VIEWS, "--json", "{tmp}/model.pt", setup=views.model), "model.pt"
        ),
        r"--json=.*model\.pt' is the same file as --model",
    ),
    Case(
        "json-is-an-image",
        intact(
            command("evaluate", *MODEL, *VIEWS, "--json", "{tmp}/egg/0.png", setup=views.model), "egg/0.png"
        ),
        r"--json=.*egg/0\.png' is the image of .*views\.csv line 2",
    ),
]


def _predict(id: str, *argv: str, match: str, setup: object = views.model) -> Case:
    return Case(id, command("predict", *argv, setup=setup), match)  # type: ignore[arg-type]


@functools.cache
def _exported() -> bytes:
    """The fit model exported with its recognizer, once."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "m.onnx"
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            main(["export", "--model", str(views.model(Path(tmp))), "--out", str(out), "--recognizer"])
        return out.read_bytes()


def _onnx(tmp: Path) -> None:
    views.model(tmp)
    (tmp / "m.onnx").write_bytes(_exported())


PREDICT = [
    _predict(
        "model-missing", "--model", "{tmp}/none.pt", "{tmp}/egg/0.png", match=r"none\.pt'? does not exist"
    ),
    _predict(
        "predict-model-fifo",
        "--model",
        "{tmp}/f.pt",
        "{tmp}/egg/0.png",
        setup=_with(files.fifo, "f.pt"),
        match=r"model .*f\.pt'? is a FIFO .*not a regular file",
    ),
    _predict(
        "predict-model-directory",
        "--model",
        "{tmp}/egg",
        "{tmp}/egg/0.png",
        match=r"model .*egg'? is a directory, not a regular file",
    ),
    _predict(
        "image-fifo",
        *MODEL,
        "{tmp}/f.png",
        setup=_with(files.fifo, "f.png"),
        match=r"f\.png is a FIFO .*not a regular file",
    ),
    _predict("image-directory", *MODEL, "{tmp}/egg", match=r"egg is a directory, not a regular file"),
    _predict(
        "image-nan",
        *MODEL,
        "{tmp}/n.tif",
        setup=_with(_nan_tiff, "n.tif"),
        match=r"n\.tif must be finite, got NaN",
    ),
    _predict(
        "reject-without-thresholds",
        *MODEL,
        "--reject",
        "{tmp}/egg/0.png",
        setup=_without_rejection,
        match=r"--reject needs a model with rejection thresholds",
    ),
    _predict(
        "reject-thresholds-nan",
        *MODEL,
        "--reject",
        "{tmp}/egg/0.png",
        setup=_tampered(reject_thresholds=[math.nan, math.nan]),
        match=r"model\.pt'?: entry 'reject_thresholds' must be .*> 0.*nan",
    ),
    _predict(
        "prep-channels-2",
        *MODEL,
        "{tmp}/egg/0.png",
        setup=_tampered(channels=2),
        match=r"model\.pt.*channels must be 1 or 3, got 2",
    ),
    Case(
        "json-is-an-image",
        intact(
            command("predict", *MODEL, "--json", "{tmp}/egg/0.png", "{tmp}/egg/0.png", setup=views.model),
            "egg/0.png",
        ),
        r"--json=.*egg/0\.png' is the same file as IMAGE",
    ),
    _predict(
        "onnx-json-is-the-graph",
        "--onnx",
        "{tmp}/m.onnx",
        "--json",
        "{tmp}/m.onnx",
        "{tmp}/egg/0.png",
        setup=_onnx,
        match=r"--json=.*m\.onnx' is the same file as --onnx",
    ),
    _predict(
        "onnx-image-fifo",
        "--onnx",
        "{tmp}/m.onnx",
        "--reject",
        "{tmp}/f.png",
        setup=lambda t: (_onnx(t), files.fifo(t / "f.png")),
        match=r"f\.png is a FIFO .*not a regular file",
    ),
]

OTHERS = [
    Case(
        "coil-extent-bogus",
        command("coil", "--folder", "{tmp}", "--extent", "yes", setup=files.coil),
        r"--extent: invalid choice: 'yes'",
    ),
]

CASES = EVALUATE + PREDICT + OTHERS


def _evaluated(n_test: int) -> object:
    """The check of ``evaluate --json {tmp}/e.json``: every one of ``n_test`` views recognized."""

    def check(out: Ran, tmp: Path) -> bool:
        record = json.loads((tmp / "e.json").read_text())
        assert record["n_test"] == n_test and record["accuracy"] == 100.0, record
        assert record["per_object"] == {"egg": 100.0, "head": 100.0} and not record["skipped"], record
        return True

    return check


#: Images of the fitted views and the answer expected for each: (file, label, pose).
SEEN = [("egg/0.png", "egg", 0.0), ("head/10.png", "head", 10.0)]


def _recognized(out: Ran, tmp: Path) -> bool:
    """``predict`` of :data:`SEEN`: each image's label and pose, known to the rejection."""
    rows = [line.split("\t") for line in out.stdout.splitlines()]
    expected = [[str(tmp / f), f"label {label}", f"pose {pose:g}"] for f, label, pose in SEEN]
    assert [row[:3] for row in rows] == expected, rows
    return True


GOOD = [
    Good(
        "evaluate-fitted-views",
        command("evaluate", *MODEL, *VIEWS, "--quiet", "--json", "{tmp}/e.json", setup=views.model),
        _evaluated(6),
    ),
    Good(
        "evaluate-exclude-seeds",
        command(
            "evaluate",
            *MODEL,
            *VIEWS,
            "--exclude-seeds",
            "--quiet",
            "--json",
            "{tmp}/e.json",
            setup=views.model,
        ),
        _evaluated(2),
    ),
    Good(
        "predict-model-reject",
        command("predict", *MODEL, "--reject", *("{tmp}/" + f for f, _, _ in SEEN), setup=views.model),
        _recognized,
    ),
    Good(
        "predict-onnx-reject",
        command(
            "predict", "--onnx", "{tmp}/m.onnx", "--reject", *("{tmp}/" + f for f, _, _ in SEEN), setup=_onnx
        ),
        _recognized,
    ),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_evaluate_predict_input_gets_a_clear_error(case: Case, tmp_path: Path) -> None:
    kind, what = outcome(case, tmp_path)
    assert kind == "clear", what


@pytest.mark.parametrize("case", params(GOOD))
def test_good_evaluate_predict_is_answered_right(case: Good, tmp_path: Path) -> None:
    kind, what = judge(case, tmp_path)
    assert kind == "right", what
