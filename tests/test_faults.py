"""Fault injection: partial writes (RLIMIT_FSIZE), killed writers, bit flips, bad output paths.

Each fault must end in a clear error that names the file or flag, and lose nothing: the
previous output survives intact, no temporary file trips a later run, no corrupted model
is ever used.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from torch_eigview.apps.cli import main
from torch_eigview.files import TEMP_MARK
from torch_eigview.io.checkpoint import load_recognizer, save_recognizer
from torch_eigview.scale.view_cache import ViewCache

from tests.io.test_checkpoint import make_recognizer

ROOT = Path(__file__).resolve().parents[1]
DEV_FULL = "/dev/full"


def _child(script: str, *args: str) -> subprocess.Popen[str]:
    """A Python process running ``script`` with this tree's package (torch on one thread)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    return subprocess.Popen(
        [sys.executable, "-c", script, *args], cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True
    )


def _state(path: Path) -> dict[str, object]:
    rec, meta = load_recognizer(path)
    return {"meta": meta, **{k: v for k, v in rec.state_dict().items()}}


def _same(a: dict[str, object], b: dict[str, object]) -> bool:
    return a.keys() == b.keys() and all(
        torch.equal(v, b[k]) if isinstance(v, torch.Tensor) else v == b[k]  # type: ignore[arg-type]
        for k, v in a.items()
    )


_UNDER_LIMIT = """
import json, os, resource, sys, torch
from tests.io.test_checkpoint import make_recognizer
from torch_eigview.apps.cli import main
from torch_eigview.files import write_json
from torch_eigview.io.checkpoint import save_recognizer
from torch_eigview.scale.view_cache import ViewCache

folder, model = sys.argv[1], os.path.join(sys.argv[1], "model.pt")
limit = os.path.getsize(model) // 2
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
out = {}
try:
    save_recognizer(make_recognizer(unit_norm=False), model)
except OSError as exc:
    out["save"] = str(exc)
try:
    write_json(os.path.join(folder, "r.json"), list(range(limit)))
except OSError as exc:
    out["json"] = str(exc)
cache = ViewCache(folder)
first = torch.rand(2, 1, 8, 8)
cache.append(first)
try:
    cache.append(torch.rand(limit // 256 + 1, 1, 8, 8))
except OSError as exc:
    out["cache"] = str(exc)
cache.append(first)
out["cache_blocks"] = [bool(torch.equal(b, first)) for b in cache()]
out["cache_bytes"] = os.path.getsize(cache.path)
cache.close()
try:
    main(["export", "--model", model, "--out", os.path.join(folder, "m.onnx"), "--recognizer"])
except SystemExit as exc:
    out["export_status"] = exc.code
print(json.dumps(out))
"""


@pytest.mark.slow
def test_partial_writes_under_a_file_size_limit(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """RLIMIT_FSIZE below the model's size: every write fails part-way and loses nothing."""
    model = tmp_path / "model.pt"
    save_recognizer(make_recognizer(), model, {"run": 1})
    before = _state(model)
    proc = _child(_UNDER_LIMIT, str(tmp_path))
    stdout, _ = proc.communicate(timeout=300)
    assert proc.returncode == 0, stdout
    out = json.loads(stdout.strip().splitlines()[-1])
    assert "could not write" in out["save"] and "model.pt" in out["save"] and "unchanged" in out["save"]
    assert "could not write" in out["json"] and "r.json" in out["json"]
    assert "rolled back to its 1 earlier block" in out["cache"]
    assert out["cache_blocks"] == [True, True] and out["cache_bytes"] == 2 * 2 * 64 * 4
    assert out["export_status"] == 2 and "m.onnx" in capfd.readouterr().err
    assert _same(_state(model), before)  # the previous model survived, bit for bit
    assert os.listdir(tmp_path) == ["model.pt"]  # no partial output, no temporary file


_KILLED_WRITER = """
import sys, time, torch
from torch_eigview.files import atomic_output
from torch_eigview.scale.view_cache import ViewCache

folder = sys.argv[1]
cache = ViewCache(folder)
for _ in range(3):
    cache.append(torch.rand(64, 1, 32, 32))
with atomic_output(folder + "/model.pt") as tmp:
    with open(tmp, "wb") as fh:
        fh.write(b"half a model")
    print("ready", flush=True)
    time.sleep(120)
"""


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_killed_writer_leaves_nothing_a_later_run_trips_over(tmp_path: Path, sig: signal.Signals) -> None:
    model = tmp_path / "model.pt"
    save_recognizer(make_recognizer(), model)
    before = _state(model)
    proc = _child(_KILLED_WRITER, str(tmp_path))
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    proc.send_signal(sig)
    proc.wait(timeout=60)
    leftovers = [n for n in os.listdir(tmp_path) if TEMP_MARK in n]
    assert len(leftovers) == 2  # the cache's file and the model's temporary file
    with ViewCache(tmp_path) as cache:  # a later run in the same folder cleans them up
        cache.append(torch.rand(2, 1, 4, 4))
        assert sorted(os.listdir(tmp_path)) == sorted(["model.pt", os.path.basename(cache.path)])
        assert [b.shape[0] for b in cache()] == [2]
    assert _same(_state(model), before)
    save_recognizer(make_recognizer(unit_norm=False), model)  # and writing there works again
    assert os.listdir(tmp_path) == ["model.pt"]


def _flip_bits(path: Path, n: int, seed: int) -> list[bytes]:
    """``n`` copies of the file, each with one random bit flipped."""
    data = path.read_bytes()
    gen = torch.Generator().manual_seed(seed)
    copies = []
    for bit in torch.randint(len(data) * 8, (n,), generator=gen).tolist():
        flipped = bytearray(data)
        flipped[bit // 8] ^= 1 << (bit % 8)
        copies.append(bytes(flipped))
    return copies


@pytest.mark.slow
def test_bit_flips_in_an_onnx_file_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from torch_eigview.io.onnx import compare_with_eager, export_recognizer, read_metadata
    from torch_eigview.io.onnx_checksum import verify_checksum

    rec = make_recognizer(torch.float32)
    path = tmp_path / "r.onnx"
    info = export_recognizer(rec, path)
    assert read_metadata(path) == info
    x = torch.rand(4, *info.image_shape, generator=torch.Generator().manual_seed(0))
    assert compare_with_eager(rec, path, x)["label_agreement"] == 1.0
    for data in _flip_bits(path, 20, seed=7):
        bad = tmp_path / "bad.onnx"
        bad.write_bytes(data)
        with pytest.raises(ValueError, match=r"bad\.onnx: checksum (mismatch|missing)"):
            verify_checksum(bad)
        with pytest.raises(ValueError, match=r"bad\.onnx"):
            read_metadata(bad)
    code = _exit(["predict", "--onnx", str(bad), str(tmp_path / "image.png")])
    assert code == 2 and "bad.onnx" in capsys.readouterr().err


def _exit(argv: list[str]) -> int:
    with pytest.raises(SystemExit) as info:
        main(argv)
    return int(info.value.code)  # type: ignore[arg-type]


def test_export_refuses_a_corrupted_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = tmp_path / "model.pt"
    save_recognizer(make_recognizer(), model)
    payload = torch.load(model, weights_only=True)
    payload["components"][0, 0] *= -1e30  # what one exponent flip does
    torch.save(payload, model)
    assert _exit(["export", "--model", str(model), "--out", str(tmp_path / "m.onnx")]) == 2
    assert "model.pt: checksum mismatch: the file is corrupted" in capsys.readouterr().err
    assert not (tmp_path / "m.onnx").exists()


# (command line before the flag, the output flag). Each run would take from seconds to hours;
# a bad output path must stop it before any of that work.
_OUTPUTS = [
    (["coil", "--folder", "{tmp}", "--alpha", "5"], "--json"),
    (["coil", "--folder", "{tmp}", "--alpha", "5"], "--save"),
    (["demo", "--png", ""], "--json"),
    (["demo"], "--png"),
    (["export", "--model", "{tmp}/model.pt"], "--out"),
    (["predict", "--onnx", "{tmp}/m.onnx", "{tmp}/a.png"], "--json"),
]
_BAD = {
    "directory": ("{tmp}", "is a directory"),
    "missing-folder": ("{tmp}/missing/out.x", "the folder '.*missing' does not exist"),
    "dev-full": (DEV_FULL, "is a character device, not a regular file"),
}


@pytest.mark.parametrize("kind", list(_BAD))
@pytest.mark.parametrize(("prefix", "flag"), _OUTPUTS, ids=[f"{p[0]}{f}" for p, f in _OUTPUTS])
def test_bad_output_path_is_refused_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], prefix: list[str], flag: str, kind: str
) -> None:
    bad, reason = (v.format(tmp=tmp_path) for v in _BAD[kind])
    if bad == DEV_FULL and not os.path.exists(DEV_FULL):
        pytest.skip("no /dev/full here")
    argv = [a.format(tmp=tmp_path) for a in prefix] + [flag, bad]
    assert _exit(argv) == 2
    err = capsys.readouterr().err
    assert f"{flag}={bad!r}" in err, err
    assert len(err.strip().splitlines()) <= 3 and "Traceback" not in err  # a message, not a crash
    assert re.search(reason, err), err


def test_output_equal_to_an_input_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = tmp_path / "model.pt"
    save_recognizer(make_recognizer(), model)
    before = model.read_bytes()
    assert _exit(["export", "--model", str(model), "--out", str(model)]) == 2
    assert "is the same file as --model" in capsys.readouterr().err
    link = tmp_path / "link.onnx"
    link.symlink_to(model)
    assert _exit(["export", "--model", str(model), "--out", str(link)]) == 2
    assert "is the same file as --model" in capsys.readouterr().err
    assert model.read_bytes() == before
    image = tmp_path / "a.png"
    image.write_bytes(b"png")
    assert _exit(["predict", "--onnx", str(tmp_path / "m.onnx"), str(image), "--json", str(image)]) == 2
    assert "is the same file as IMAGE" in capsys.readouterr().err and image.read_bytes() == b"png"
    json_path = str(tmp_path / "r.out")
    assert (
        _exit(["coil", "--folder", str(tmp_path), "--alpha", "5", "--json", json_path, "--save", json_path])
        == 2
    )
    assert "name the same file" in capsys.readouterr().err
