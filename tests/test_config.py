"""The work limits: a configuration the library reads and the command sets, never the
environment behind the library's back."""

from __future__ import annotations

import threading

import pytest

from torch_eigview import config_context, get_config, set_config
from torch_eigview.apps.cli import limits_from_environment
from torch_eigview.config import DEFAULTS
from torch_eigview.geometry.angles import angle_range


def test_context_raises_a_limit_and_restores_it() -> None:
    with pytest.raises(
        ValueError, match=r"asks for 7201 views per object, more than the limit of 3600 \(max_views\)"
    ):
        angle_range(0.0, 360.0, 0.05, "synth")
    with config_context(max_views=7201) as config:
        assert config["max_views"] == 7201
        assert len(angle_range(0.0, 360.0, 0.05, "synth")) == 7201
    assert get_config() == dict(DEFAULTS)


def test_environment_is_not_read_by_the_library(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("EIGVIEW_MAX_VIEWS", "10")
    assert len(angle_range(0.0, 100.0, 1.0, "synth")) == 101  # the default limit holds
    assert limits_from_environment() == {"max_views": 10}  # the command's reading


def test_set_config_stays_in_its_thread() -> None:
    seen: list[int] = []

    def other() -> None:
        seen.append(get_config()["max_views"])

    try:
        set_config(max_views=50)
        thread = threading.Thread(target=other)
        thread.start()
        thread.join()
        assert get_config()["max_views"] == 50 and seen == [DEFAULTS["max_views"]]
    finally:
        set_config(max_views=DEFAULTS["max_views"])


@pytest.mark.parametrize(
    ("limits", "error", "match"),
    [
        ({"max_view": 10}, TypeError, r"unknown limit\(s\) \['max_view'\]; the limits are"),
        ({"max_views": 0}, ValueError, r"max_views must be a positive int, got 0"),
        ({"max_views": 2.5}, ValueError, r"max_views must be a positive int, got 2\.5"),
        ({"max_views": True}, ValueError, r"max_views must be a positive int, got True"),
    ],
)
def test_bad_limits_are_named(limits: dict[str, object], error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match), config_context(**limits):  # type: ignore[arg-type]
        pass


@pytest.mark.parametrize("text", ["0", "-3", "1_0", "ten", "1e3", "٣"])
def test_command_refuses_a_bad_environment_value(text: str) -> None:
    with pytest.raises(
        ValueError, match=rf"environment variable EIGVIEW_MAX_VIEWS={text!r} must be a positive integer"
    ):
        limits_from_environment({"EIGVIEW_MAX_VIEWS": text})
    assert limits_from_environment({"EIGVIEW_MAX_VIEWS": " "}) == {}
