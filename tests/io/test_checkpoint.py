"""Tests for ``save_recognizer`` / ``load_recognizer``: round trip, safe loading, bad files."""

from __future__ import annotations

import errno
import math
import os
import re
from pathlib import Path
from typing import BinaryIO

import pytest
import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.io.checkpoint import (
    FORMAT,
    FORMAT_VERSION,
    STATE_DICT_FORMAT,
    load_recognizer,
    load_state_dict,
    save_recognizer,
    save_state_dict,
)
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer

IMAGE_SHAPE = (1, 4, 6)
METADATA = {"command": "coil", "alpha": 10.0, "method": "nvs", "objects": [1, 2], "accuracy": 93.5}


def randn(*shape: int, seed: int, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.randn(*shape, generator=gen, dtype=torch.float64).to(dtype)


def make_recognizer(
    dtype: torch.dtype = torch.float64,
    *,
    unit_norm: bool = True,
    eigenvalues: bool = True,
    image_shape: bool = True,
    label_names: bool = True,
) -> NearestNeighborRecognizer:
    """A recognizer fitted on random views of 3 labelled objects."""
    views = randn(18, *IMAGE_SHAPE, seed=0, dtype=dtype)
    flat = views.flatten(1)
    x_fit = flat / flat.norm(dim=1, keepdim=True) if unit_norm else flat
    space = Eigenspace(4).fit(x_fit)
    projection = EigenProjection.from_tensors(
        space.mean_,
        space.components_,
        space.eigenvalues_ if eigenvalues else None,
        IMAGE_SHAPE if image_shape else None,
        unit_norm=unit_norm,
    )
    labels = torch.tensor([1, 2, 5] * 6)
    poses = torch.arange(18, dtype=dtype) * 5.0
    names = ["cup", "duck", "car"] if label_names else None
    return NearestNeighborRecognizer.from_views(projection, views, labels, poses, names)


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    path = tmp_path / "model.pt"
    save_recognizer(make_recognizer(), path, METADATA)
    return path


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64], ids=["float32", "float64"])
@pytest.mark.parametrize(
    "variant",
    [
        dict(),
        dict(unit_norm=False),
        dict(eigenvalues=False, image_shape=False, label_names=False),
    ],
    ids=["full", "no-unit-norm", "minimal"],
)
def test_round_trip(tmp_path: Path, dtype: torch.dtype, variant: dict[str, bool]) -> None:
    rec = make_recognizer(dtype, **variant)
    path = tmp_path / "model.pt"
    save_recognizer(rec, str(path), METADATA)
    loaded, metadata = load_recognizer(path)

    assert metadata == METADATA
    assert loaded.projection.unit_norm == rec.projection.unit_norm
    assert loaded.projection.image_shape == rec.projection.image_shape
    assert loaded.label_names == rec.label_names
    assert repr(loaded) == repr(rec)
    for name, buffer in rec.state_dict().items():
        if isinstance(buffer, torch.Tensor):
            torch.testing.assert_close(loaded.state_dict()[name], buffer, atol=0, rtol=0)

    x = randn(9, *IMAGE_SHAPE, seed=1, dtype=dtype)
    want, got = rec.predict(x), loaded.predict(x)
    for field in ("labels", "poses", "distances", "indices"):
        torch.testing.assert_close(getattr(got, field), getattr(want, field), atol=0, rtol=0)
    if rec.projection.unit_norm:
        torch.testing.assert_close(loaded.predict(3 * x).indices, want.indices, atol=0, rtol=0)


def test_metadata_defaults_to_empty(tmp_path: Path) -> None:
    path = tmp_path / "model.pt"
    save_recognizer(make_recognizer(), path)
    assert load_recognizer(path)[1] == {}


def test_file_loads_with_weights_only(saved: Path) -> None:
    payload = torch.load(saved, weights_only=True)
    assert payload["format"] == FORMAT and payload["version"] == FORMAT_VERSION
    assert payload["unit_norm"] is True and list(payload["image_shape"]) == list(IMAGE_SHAPE)
    assert payload["metadata"] == METADATA


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="does not exist"):
        load_recognizer(tmp_path / "nope.pt")


def test_truncated_file(saved: Path) -> None:
    data = saved.read_bytes()
    saved.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="could not be read as a torch_eigview model"):
        load_recognizer(saved)


def test_text_file(tmp_path: Path) -> None:
    path = tmp_path / "notes.txt"
    path.write_text("not a model\n")
    with pytest.raises(ValueError, match="could not be read as a torch_eigview model"):
        load_recognizer(path)


@pytest.mark.parametrize(
    "payload",
    [{"weights": torch.zeros(3)}, [1, 2, 3], {"format": "something.else", "version": 1}],
    ids=["dict", "list", "other-format"],
)
def test_foreign_torch_file(tmp_path: Path, payload: object) -> None:
    path = tmp_path / "other.pt"
    torch.save(payload, path)
    with pytest.raises(ValueError, match="is not a torch_eigview recognizer"):
        load_recognizer(path)


def test_wrong_version(saved: Path) -> None:
    payload = torch.load(saved, weights_only=True)
    payload["version"] = FORMAT_VERSION + 1
    torch.save(payload, saved)
    with pytest.raises(
        ValueError, match=f"format version {FORMAT_VERSION + 1}.*reads version {FORMAT_VERSION}"
    ):
        load_recognizer(saved)


def test_save_rejects_non_recognizer(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="recognizer must be a NearestNeighborRecognizer"):
        save_recognizer(make_recognizer().projection, tmp_path / "m.pt")  # type: ignore[arg-type]


def test_header_only_payload(tmp_path: Path) -> None:
    path = tmp_path / "header.pt"
    torch.save({"format": FORMAT, "version": FORMAT_VERSION}, path)
    with pytest.raises(ValueError, match="torch_eigview"):
        load_recognizer(path)


def test_metadata_that_cannot_be_loaded_is_refused_at_save(tmp_path: Path) -> None:
    path = tmp_path / "model.pt"
    metadata = {"root": Path("/data/coil-20-proc")}
    with pytest.raises(TypeError, match="metadata must hold JSON values"):
        save_recognizer(make_recognizer(), path, metadata)
    assert not path.exists()


def _flip(path: Path, bit: int) -> None:
    data = bytearray(path.read_bytes())
    data[bit // 8] ^= 1 << (bit % 8)
    path.write_bytes(bytes(data))


def test_random_bit_flips_are_refused_or_harmless(saved: Path) -> None:
    """Each of 20 random single-bit flips is refused with the file's name, or lands where
    torch never reads (zip padding, header fields) and the model loads bit-identically."""
    want, _ = load_recognizer(saved)
    original = saved.read_bytes()
    gen = torch.Generator().manual_seed(16)
    refused = 0
    for bit in torch.randint(len(original) * 8, (20,), generator=gen).tolist():
        saved.write_bytes(original)
        _flip(saved, bit)
        try:
            got, metadata = load_recognizer(saved)
        except ValueError as exc:
            assert str(saved) in str(exc), f"bit {bit}: {exc}"
            refused += 1
            continue
        assert metadata == METADATA and got.label_names == want.label_names, f"bit {bit}"
        for name, buffer in want.state_dict().items():
            other = got.state_dict()[name]
            same = torch.equal(other, buffer) if isinstance(buffer, torch.Tensor) else other == buffer
            assert same, f"bit {bit} changed {name} and the file still loaded"
    assert refused >= 5  # most of the file is tensor data and pickle, which are checked


@pytest.mark.parametrize("entry", ["components", "codes", "poses", "label_names", "metadata", "unit_norm"])
def test_changed_entry_is_a_checksum_mismatch(saved: Path, entry: str) -> None:
    payload = torch.load(saved, weights_only=True)
    value = payload[entry]
    if isinstance(value, torch.Tensor):
        flat = value.view(-1)
        flat[3] = torch.nextafter(flat[3], torch.tensor(math.inf, dtype=flat.dtype))  # one ulp
    elif entry == "label_names":
        payload[entry] = ["cup", "duck", "cat"]
    elif entry == "metadata":
        payload[entry] = {**value, "accuracy": 5.0}
    else:
        payload[entry] = not value
    torch.save(payload, saved)
    with pytest.raises(
        ValueError, match=rf"{re.escape(str(saved))}: checksum mismatch: the file is corrupted"
    ):
        load_recognizer(saved)


def test_version_1_file_without_checksum_is_refused(saved: Path) -> None:
    payload = torch.load(saved, weights_only=True)
    payload["version"] = 1
    del payload["sha256"]
    torch.save(payload, saved)
    with pytest.raises(ValueError, match=r"format version 1.*no checksum: save the model again"):
        load_recognizer(saved)


def test_save_replaces_atomically_and_keeps_the_old_file_on_failure(
    saved: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    before = saved.read_bytes()

    def failing_save(obj: object, f: BinaryIO) -> None:
        f.write(b"PK\x03\x04 half a zip")
        f.flush()
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(torch, "save", failing_save)
    with pytest.raises(
        OSError, match=r"could not write .*model\.pt.*No space left.*previous file.*unchanged"
    ):
        save_recognizer(make_recognizer(unit_norm=False), saved)
    assert saved.read_bytes() == before
    assert os.listdir(saved.parent) == ["model.pt"]  # the temporary file is gone


def test_bad_output_paths_are_refused_before_writing(tmp_path: Path) -> None:
    rec = make_recognizer()
    with pytest.raises(ValueError, match=r"path='.*' is a directory"):
        save_recognizer(rec, tmp_path)
    with pytest.raises(ValueError, match=r"path='.*missing/m.pt': the folder '.*missing' does not exist"):
        save_recognizer(rec, tmp_path / "missing" / "m.pt")
    if os.path.exists("/dev/full"):
        with pytest.raises(ValueError, match=r"path='/dev/full' is a character device"):
            save_recognizer(rec, "/dev/full")
    assert os.listdir(tmp_path) == []


def test_state_dict_round_trip_and_checksum(tmp_path: Path) -> None:
    projection = make_recognizer().projection
    path = tmp_path / "projection.pt"
    save_state_dict(projection.state_dict(), path)
    state = load_state_dict(path)
    for name, value in projection.state_dict().items():
        assert torch.equal(state[name], value) if isinstance(value, torch.Tensor) else state[name] == value
    copy = EigenProjection(24, 4).double()
    copy.load_state_dict(state)
    assert copy.image_shape == projection.image_shape and copy.unit_norm == projection.unit_norm
    payload = torch.load(path, weights_only=True)
    assert payload["format"] == STATE_DICT_FORMAT
    payload["state_dict"]["mean"][0] += 1
    torch.save(payload, path)
    with pytest.raises(ValueError, match=r"projection\.pt: checksum mismatch"):
        load_state_dict(path)
    with pytest.raises(TypeError, match=r"state_dict\['x'\] must be a tensor or JSON-like"):
        save_state_dict({"x": object()}, path)
    with pytest.raises(ValueError, match="is not a torch_eigview state_dict"):
        load_state_dict(_saved_recognizer(tmp_path))


def _saved_recognizer(folder: Path) -> Path:
    path = folder / "recognizer.pt"
    save_recognizer(make_recognizer(), path)
    return path
