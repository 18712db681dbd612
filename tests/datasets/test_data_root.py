"""Where the data sets are looked for: an argument, then ``TORCH_EIGVIEW_DATA``, then
``~/torch_eigview_data`` (scikit-learn's ``get_data_home`` order); never the source checkout."""

from __future__ import annotations

from pathlib import Path

import pytest

from torch_eigview.datasets import DATA_ENV, find_coil_root, get_data_home


def test_env_names_the_data_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "coil-20-proc").mkdir()
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert get_data_home() == tmp_path
    assert find_coil_root() == tmp_path / "coil-20-proc"
    (tmp_path / "coil-100").mkdir()
    assert find_coil_root(name="coil-100") == tmp_path / "coil-100"


def test_argument_beats_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    given = tmp_path / "mine"
    (given / "coil-20-proc").mkdir(parents=True)
    monkeypatch.setenv(DATA_ENV, str(tmp_path / "elsewhere"))
    assert find_coil_root(given) == given
    assert find_coil_root(str(given)) == given
    assert get_data_home(given) == given
    assert find_coil_root(data_home=given) == given / "coil-20-proc"


@pytest.mark.parametrize("value", [None, ""], ids=["unset", "empty"])
def test_default_is_in_the_home_folder(
    value: str | None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HOME", str(tmp_path))
    if value is None:
        monkeypatch.delenv(DATA_ENV, raising=False)
    else:
        monkeypatch.setenv(DATA_ENV, value)
    assert get_data_home() == tmp_path / "torch_eigview_data"
    checkout = Path(__file__).resolve().parents[2]
    assert checkout not in get_data_home().parents  # nothing inside the source tree


def test_missing_from_env_says_where(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    with pytest.raises(ValueError, match="must be an existing directory") as info:
        find_coil_root()
    message = str(info.value)
    assert str(tmp_path / "coil-20-proc") in message  # the folder expected
    assert f"from {DATA_ENV}={tmp_path}" in message  # why there
    assert "coil-20-proc/" in message and DATA_ENV in message and "--folder DIR" in message


def test_missing_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    with pytest.raises(
        ValueError, match=r"'.*nope' \(given as the folder itself\) must be an existing directory"
    ):
        find_coil_root(tmp_path / "nope")
    with pytest.raises(ValueError, match=f"{DATA_ENV} being unset"):
        find_coil_root(name="no-such-data-set")


def test_bad_types() -> None:
    with pytest.raises(TypeError, match="root must be a str, a path or None, got int"):
        find_coil_root(3)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="name must be a str"):
        find_coil_root(None, name=5)  # type: ignore[arg-type]
