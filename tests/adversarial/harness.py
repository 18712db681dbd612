"""How an adversarial case is run and judged: one bad input, one expected clear error.

A :class:`Case` calls one entry point with one bad input. Its outcome is one of

- ``clear``: a ValueError or TypeError (for the command: exit status 2 and a message on
  stderr) whose message matches the case's pattern, which names the argument or file, the
  constraint and the value given;
- ``unhelpful``: any other exception (a raw traceback), or a message that does not match;
- ``hang``: no answer within :data:`TIMEOUT` seconds;
- ``silent``: no error at all, or a result that is not finite;
- ``lost``: the case's own check of the files it wrote failed (data destroyed).

``python -m tests.adversarial.tally`` prints the tally of every case.
"""

from __future__ import annotations

import contextlib
import io
import math
import re
import signal
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from torch_eigview.apps.cli import main

#: Seconds a case may take before it counts as a hang (every case answers in well under one).
TIMEOUT = 20


class CommandError(Exception):
    """The command exited with status 2; the message is what it printed on stderr."""


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


def command(*argv: str, setup: Callable[[Path], object] | None = None) -> Callable[[Path], object]:
    """A case that runs ``eigview`` with ``argv`` (``{tmp}`` is the case's folder, which
    ``setup`` fills first); a non-zero exit status raises :class:`CommandError`."""

    def body(tmp: Path) -> object:
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                status = main([a.format(tmp=tmp) for a in argv])
            except SystemExit as exc:
                status = exc.code  # type: ignore[assignment]
        if status:
            raise CommandError(f"exit status {status}: {err.getvalue()}")
        return status

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
        with deadline():
            out = case.run(tmp)
    except (Expired, TimeoutError) as exc:
        return "hang", str(exc)
    except LostData as exc:
        return "lost", str(exc)
    except Exception as exc:  # any other exception is the finding
        message = str(exc)
        expected = isinstance(exc, (*case.errors, CommandError))
        if expected and re.search(case.match, message, flags=re.DOTALL) and "Traceback" not in message:
            return "clear", message
        return "unhelpful", f"{type(exc).__name__}: {message}"
    return "silent", f"no error; returned {out!r:.200}" if _finite(out) else "non-finite result"
