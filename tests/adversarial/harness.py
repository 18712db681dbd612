"""How an adversarial case is run and judged: one bad input, one expected clear error; one
good input, one right answer.

A :class:`Case` calls one entry point with one bad input. Its outcome is one of

- ``clear``: a ValueError or TypeError whose message matches the case's pattern, or for the
  command a non-zero exit status whose error lines on stderr match it (:func:`error_lines`:
  the ``eigview: error: ...`` lines, argparse's final ``eigview <cmd>: error: ...`` line,
  never the usage text, a warning or a progress line). Every pattern names what is wrong
  (the argument, flag or file) and the cause (``--threads.*must be.*>= ?1``), never only a
  file name or a type;
- ``unhelpful``: any other exception (a raw traceback), or a message that does not match;
- ``hang``: no answer within :data:`TIMEOUT` seconds;
- ``silent``: no error at all, or a result that is not finite;
- ``lost``: the case's own check of the files it wrote failed (data destroyed).

A case with ``warns`` is input that is well-formed but likely wrong, where the package goes
on and says so: it is ``clear`` when the call succeeds with a warning that matches (a
Python warning, or the command's ``eigview: warning: ...`` line on stderr), or fails with a
matching error; ``silent`` when it succeeds without one.

A :class:`Good` calls one entry point with one valid input (a ``--threads 1`` run, a valid
manifest), which must succeed with a sane answer: ``right``, or ``wrong`` for an error, a
hang or an answer its check refuses (:func:`judge`). A validation that refuses good input
is as much a fault as one that lets bad input through.

``python -m tests.adversarial.tally`` prints the tally of every case.
"""

from __future__ import annotations

import contextlib
import io
import math
import re
import signal
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from torch_eigview.apps.cli import main

#: Seconds a case may take before it counts as a hang (every case answers in well under one).
TIMEOUT = 20


# Patterns several modules share: each names what is wrong and the cause.

#: ``-k/--components VALUE`` refused by argparse (``.format(value)``, the value as a regex).
COMPONENTS = r"--components must be an int >= ?1 or a fraction in \(0, 1\), got '{}'"
#: A model file that torch cannot read: the cause, after the file's name.
DAMAGED = r"could not be read as a torch_eigview model \((damaged|truncated)"
#: A file that is not image data, and an empty one: the cause, not imageio's lack of a plugin.
NOT_AN_IMAGE = r"(is not an? (\w+ )?image|not (PNG|image) data|damaged|corrupt|unknown (image )?format)"
EMPTY = r"(is empty|0 bytes|empty file)"


def threads_error(value: str) -> str:
    """The error expected for ``--threads VALUE``: the flag, the bound 1 and the value."""
    return rf"--threads\b.*must be .*>= ?1.*'{re.escape(value)}'"


class CommandError(Exception):
    """The command exited with a non-zero status; ``stderr`` is what it printed there."""

    def __init__(self, status: object, stderr: str) -> None:
        super().__init__(f"exit status {status}: {stderr}")
        self.status = status
        self.stderr = stderr


@dataclass(frozen=True)
class Ran:
    """What a command that exited with status 0 printed."""

    stdout: str
    stderr: str


#: The start of an error line: ``eigview: error: `` (the command's handler), ``eigview fit:
#: error: `` (argparse, after its usage text), ``eigview predict: error: `` (one image).
_ERROR_LINE = re.compile(r"^eigview(?: [\w-]+)?: error: ")
#: A warning line of the command's: ``eigview: warning: ...``.
_WARNING_LINE = re.compile(r"^eigview(?: [\w-]+)?: warning: ")
#: A line of the command's own that is not part of an error message (a warning, a summary).
_OWN_LINE = re.compile(r"^eigview(?: [\w-]+)?: ")


def error_lines(stderr: str) -> str:
    """The error messages a command printed on ``stderr``, one a line, without their
    ``eigview...: error:`` prefix: the usage text before argparse's error, warnings, progress
    and summary lines left out. A message that runs over several lines (a library's text
    quoted in it) keeps its following lines up to the next line of the command's own."""
    messages: list[list[str]] = []
    inside = False
    for line in stderr.splitlines():
        start = _ERROR_LINE.match(line)
        if start:
            messages.append([line[start.end() :]])
            inside = True
        elif _OWN_LINE.match(line) or line.startswith("usage:"):
            inside = False
        elif inside:
            messages[-1].append(line)
    return "\n".join("\n".join(m) for m in messages)


class LostData(AssertionError):
    """A case's check of the files it wrote failed."""


class Expired(BaseException):
    """Raised by :func:`deadline`: a BaseException, so that the command's own handler of
    Exception (which prints ``eigview: error: ...`` and exits 2) cannot turn a hang into an
    ordinary error."""


@dataclass(frozen=True)
class Case:
    """One bad input: ``run(tmp)`` calls an entry point; ``match`` is the error expected."""

    id: str
    run: Callable[[Path], object]
    match: str
    #: The exception types that count as a clear answer (torch's ``load_state_dict``
    #: reports a size mismatch as a RuntimeError, its own convention).
    errors: tuple[type[Exception], ...] = (ValueError, TypeError)
    #: Where the package's message does not say the cause yet: what it should say. The
    #: case is then expected not to be clear (a strict xfail in :func:`params`), so that
    #: the fix of the message shows as a test to update.
    todo: str = ""
    #: A warning (or a matching error) is the clear answer: the input may be meant.
    warns: bool = False


def _warning_text(out: object, caught: list[warnings.WarningMessage]) -> str:
    """The warnings a successful call gave: Python's, then the command's own lines."""
    lines = [str(w.message) for w in caught]
    if isinstance(out, Ran):
        lines += [
            line.split("warning: ", 1)[1] for line in out.stderr.splitlines() if _WARNING_LINE.match(line)
        ]
    return "\n".join(lines)


def params(cases: Sequence[Case | Good]) -> list[Any]:
    """``cases`` as pytest parameters named by their ids, a case with a ``todo`` marked as
    a strict xfail that gives it as the reason."""
    import pytest

    return [
        pytest.param(c, id=c.id, marks=pytest.mark.xfail(strict=True, reason=c.todo))
        if getattr(c, "todo", "")
        else pytest.param(c, id=c.id)
        for c in cases
    ]


def command(*argv: str, setup: Callable[[Path], object] | None = None) -> Callable[[Path], object]:
    """A case that runs ``eigview`` with ``argv`` (``{tmp}`` is the case's folder, which
    ``setup`` fills first); a non-zero exit status raises :class:`CommandError`, status 0
    returns what it printed (:class:`Ran`)."""

    def body(tmp: Path) -> object:
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            try:
                status = main([a.format(tmp=tmp) for a in argv])
            except SystemExit as exc:
                status = exc.code  # type: ignore[assignment]
        if status:
            raise CommandError(status, err.getvalue())
        return Ran(out.getvalue(), err.getvalue())

    def run(tmp: Path) -> object:
        if setup is not None:
            setup(tmp)
        return body(tmp)

    run.setup = setup  # type: ignore[attr-defined]  # for intact(): snapshot between the two
    run.body = body  # type: ignore[attr-defined]
    return run


def intact(run: Callable[[Path], object], *names: str) -> Callable[[Path], object]:
    """``run``, then a check that the files ``names`` (in the case's folder), made by its
    setup, still hold their bytes: whatever ``run`` answers, a changed input is lost data."""

    def check(tmp: Path) -> object:
        before: dict[str, bytes] = {}

        def snapshot() -> None:
            before.update({n: (tmp / n).read_bytes() for n in names if (tmp / n).is_file()})

        try:
            return run(tmp) if not names else _after_setup(run, tmp, snapshot)
        finally:
            changed = [n for n, data in before.items() if (tmp / n).read_bytes() != data]
            if changed:
                raise LostData(f"the command changed its input {changed}")

    return check


def _after_setup(run: Callable[[Path], object], tmp: Path, snapshot: Callable[[], None]) -> object:
    setup = getattr(run, "setup", None)
    if setup is not None:
        setup(tmp)
    snapshot()
    return getattr(run, "body", run)(tmp)


@contextlib.contextmanager
def deadline(seconds: int = TIMEOUT) -> Iterator[None]:
    """Raises :class:`Expired` in the calling thread after ``seconds`` (a blocked open too)."""

    def expire(signum: int, frame: object) -> None:
        raise Expired(f"no answer within {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _finite(out: Any) -> bool:
    if isinstance(out, torch.Tensor):
        return not out.is_floating_point() or bool(torch.isfinite(out).all())
    if isinstance(out, (tuple, list)):
        return all(_finite(o) for o in out)
    if isinstance(out, float):
        return math.isfinite(out)
    return True


def outcome(case: Case, tmp: Path) -> tuple[str, str]:
    """(kind, what happened) for one case run in the empty folder ``tmp``."""
    try:
        with deadline(), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            out = case.run(tmp)
    except (Expired, TimeoutError) as exc:
        return "hang", str(exc)
    except LostData as exc:
        return "lost", str(exc)
    except Exception as exc:  # any other exception is the finding
        message = error_lines(exc.stderr) if isinstance(exc, CommandError) else str(exc)
        expected = isinstance(exc, (*case.errors, CommandError))
        if expected and re.search(case.match, message, flags=re.DOTALL) and "Traceback" not in str(exc):
            return "clear", message
        if isinstance(exc, CommandError) and message:  # the error lines, not the usage text
            return "unhelpful", f"CommandError: exit status {exc.status}: {message}"
        return "unhelpful", f"{type(exc).__name__}: {exc}"
    if case.warns:
        said = _warning_text(out, caught)
        if re.search(case.match, said, flags=re.DOTALL):
            return "clear", said
        return "silent", f"no matching warning ({said[:200]!r}); returned {out!r:.200}"
    return "silent", f"no error; returned {out!r:.200}" if _finite(out) else "non-finite result"


@dataclass(frozen=True)
class Good:
    """One good input: ``run(tmp)`` calls an entry point, which must succeed; ``check(out,
    tmp)`` says whether its answer ``out`` is right (False, or an AssertionError whose
    message says what is wrong, when it is not)."""

    id: str
    run: Callable[[Path], object]
    check: Callable[[Any, Path], bool]


def judge(good: Good, tmp: Path) -> tuple[str, str]:
    """(``right`` or ``wrong``, what happened) for one good input run in the empty folder ``tmp``."""
    try:
        with deadline():
            out = good.run(tmp)
    except (Expired, TimeoutError) as exc:
        return "wrong", str(exc)
    except CommandError as exc:  # a refused good input is the finding
        return "wrong", f"CommandError: exit status {exc.status}: {error_lines(exc.stderr) or exc.stderr}"
    except Exception as exc:
        return "wrong", f"{type(exc).__name__}: {exc}"
    try:
        right = good.check(out, tmp) and _finite(out)
    except AssertionError as exc:
        return "wrong", f"{exc}; returned {out!r:.200}"
    return ("right", f"{out!r:.200}") if right else ("wrong", f"returned {out!r:.200}")
