"""Where the COIL images are looked for: ``--root`` (``root``), then ``TORCH_EIGVIEW_DATA``, then ../shared/data."""

from __future__ import annotations

from pathlib import Path

import pytest

from torch_eigview.datasets import DATA_ENV, default_data_root, find_coil_root


def test_env_names_the_data_root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "coil-20-proc").mkdir()
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert default_data_root() == tmp_path
    assert find_coil_root() == tmp_path / "coil-20-proc"
    (tmp_path / "coil-100").mkdir()
    assert find_coil_root(name="coil-100") == tmp_path / "coil-100"


def test_flag_beats_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    given = tmp_path / "mine"
    given.mkdir()
    monkeypatch.setenv(DATA_ENV, str(tmp_path / "elsewhere"))
    assert find_coil_root(given) == given
    assert find_coil_root(str(given)) == given


@pytest.mark.parametrize("value", [None, ""], ids=["unset", "empty"])
def test_default_is_beside_the_checkout(value: str | None, monkeypatch: pytest.MonkeyPatch) -> None:
    if value is None:
        monkeypatch.delenv(DATA_ENV, raising=False)
    else:
        monkeypatch.setenv(DATA_ENV, value)
    checkout = Path(__file__).resolve().parents[2]
    assert default_data_root() == checkout.parent / "shared" / "data"


def test_missing_from_env_says_where(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    with pytest.raises(ValueError, match="must be an existing directory") as info:
        find_coil_root()
    message = str(info.value)
    assert str(tmp_path / "coil-20-proc") in message  # the folder expected
    assert f"from {DATA_ENV}={tmp_path}" in message  # why there
    assert "coil-20-proc/" in message and DATA_ENV in message and "--root DIR" in message


def test_missing_flag_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    with pytest.raises(
        ValueError, match=r"root='.*nope' \(given with --root\) must be an existing directory"
    ):
        find_coil_root(tmp_path / "nope")
    with pytest.raises(ValueError, match=f"{DATA_ENV} being unset"):
        find_coil_root(name="no-such-data-set")


def test_bad_types() -> None:
    with pytest.raises(TypeError, match="root must be a str, a path or None, got int"):
        find_coil_root(3)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="name must be a str"):
        find_coil_root(None, name=5)  # type: ignore[arg-type]
