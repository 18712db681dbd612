"""The command line explains itself: every option has help and shows its default, a flag
name means one thing in every command, and ``--version`` answers."""

from __future__ import annotations

import argparse

import pytest

from torch_eigview import __version__
from torch_eigview.apps.cli import build_parser, main


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [
        a
        for a in parser._actions
        if a.option_strings and not isinstance(a, argparse._HelpAction) and a.help != argparse.SUPPRESS
    ]


@pytest.mark.parametrize("command", sorted(_commands()))
def test_every_option_has_help_and_shows_its_default(command: str) -> None:
    parser = _commands()[command]
    text = parser.format_help()
    for action in _options(parser):
        flag = action.option_strings[-1]
        assert action.help, f"eigview {command} {flag} has no help"
        shown = action.default not in (None, False)
        if shown:
            # The formatter appends "(default: ...)"; the help names the flag's default value.
            help_text = parser._get_formatter()._expand_help(action)  # what --help prints for it
            assert "(default:" in help_text, f"eigview {command} {flag} does not show its default"
    assert parser.description, f"eigview {command} has no description"
    assert "(default: None)" not in text and "(default: False)" not in text


def test_a_flag_means_one_thing_in_every_command() -> None:
    """The same flag stores the same destination with the same kind of value everywhere."""
    seen: dict[str, tuple[str, str]] = {}
    for command, parser in _commands().items():
        for action in _options(parser):
            for flag in action.option_strings:
                kind = (action.dest, type(action).__name__)
                if flag in seen:
                    assert seen[flag][1:] == (kind[1],) and seen[flag][0] == kind[0], (
                        f"{flag} is {seen[flag]} in one command and {kind} in eigview {command}"
                    )
                seen.setdefault(flag, kind)
    # The names that once meant two things: --seeds (azimuths, or a count) and --root.
    assert "--circle" in seen and seen["--seeds"][0] == "seeds"
    coil = {f for a in _options(_commands()["coil"]) for f in a.option_strings}
    assert "--root" not in coil and "--folder" in coil and "--no-extent" not in coil


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"eigview {__version__}"


def test_top_level_help_lists_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for command in _commands():
        assert f"eigview {command}" in out, f"the top-level help shows no example of eigview {command}"
