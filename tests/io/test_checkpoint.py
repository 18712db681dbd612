"""Tests for ``save_recognizer`` / ``load_recognizer``: round trip, safe loading, bad files."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.io.checkpoint import FORMAT, FORMAT_VERSION, load_recognizer, save_recognizer
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
    projection = EigenProjection(
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
    save_recognizer(path, make_recognizer(), METADATA)
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
    save_recognizer(str(path), rec, METADATA)
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
    save_recognizer(path, make_recognizer())
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
        save_recognizer(tmp_path / "m.pt", make_recognizer().projection)  # type: ignore[arg-type]


def test_header_only_payload(tmp_path: Path) -> None:
    path = tmp_path / "header.pt"
    torch.save({"format": FORMAT, "version": FORMAT_VERSION}, path)
    with pytest.raises(ValueError, match="torch_eigview"):
        load_recognizer(path)


def test_metadata_that_cannot_be_loaded_is_refused_at_save(tmp_path: Path) -> None:
    path = tmp_path / "model.pt"
    metadata = {"root": Path("/data/coil-20-proc")}
    with pytest.raises(TypeError, match="metadata must hold JSON values"):
        save_recognizer(path, make_recognizer(), metadata)
    assert not path.exists()
