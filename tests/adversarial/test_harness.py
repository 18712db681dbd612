"""The judge itself: a command's case is matched against its error lines only (never the
usage text argparse prints before them, a warning or a summary line), and a good case is
right only when it runs and its check holds."""

from __future__ import annotations

from pathlib import Path

from tests.adversarial.harness import Case, Good, command, error_lines, judge, outcome

STDERR = """usage: eigview coil [-h] [--root ROOT] [--threads N]
                    [--components K]
eigview: warning: object 2: elevation could not be measured
eigview coil: error: argument --threads: --threads must be an integer >= 1, got '0'
"""


def test_error_lines_leave_out_usage_warnings_and_summaries() -> None:
    assert error_lines(STDERR) == "argument --threads: --threads must be an integer >= 1, got '0'"
    two = "eigview predict: error: image a.png is a FIFO\neigview predict: error: image b.png: bad\nsecond line\n"
    summary = "eigview predict: 2 of 2 images failed\n"
    assert error_lines(two + summary) == "image a.png is a FIFO\nimage b.png: bad\nsecond line"
    assert error_lines("Traceback (most recent call last):\n  ...\n") == ""


def test_a_pattern_that_only_the_usage_text_matches_is_unhelpful(tmp_path: Path) -> None:
    """``[--threads N]`` and ``--components`` are in the usage text, not in the error line
    (argparse's own refusal of a choice, so that only the judge is tested here)."""
    run = command("coil", "--folder", "{tmp}", "--extent", "yes")
    assert outcome(Case("usage", run, r"\[--threads N\]"), tmp_path)[0] == "unhelpful"
    assert outcome(Case("usage", run, r"--components"), tmp_path)[0] == "unhelpful"
    kind, what = outcome(Case("error", run, r"--extent: invalid choice: 'yes'"), tmp_path)
    assert kind == "clear" and "usage" not in what, what


def test_a_good_case_is_right_only_when_it_runs_and_its_check_holds(tmp_path: Path) -> None:
    def refuse(tmp: Path) -> None:
        raise ValueError("refused a good input")

    def fail(out: object, tmp: Path) -> bool:
        raise AssertionError("a wrong answer")

    assert judge(Good("right", lambda t: 1.0, lambda out, t: out == 1.0), tmp_path)[0] == "right"
    assert judge(Good("false", lambda t: 1.0, lambda out, t: False), tmp_path)[0] == "wrong"
    assert judge(Good("check", lambda t: 1.0, fail), tmp_path) == ("wrong", "a wrong answer; returned 1.0")
    assert judge(Good("refused", refuse, lambda out, t: True), tmp_path)[0] == "wrong"
    assert judge(Good("nan", lambda t: float("nan"), lambda out, t: True), tmp_path)[0] == "wrong"


def test_a_warning_case_is_clear_only_with_a_matching_warning(tmp_path: Path) -> None:
    """``warns``: a matching Python warning or ``eigview: warning:`` line is clear; none, or
    another, is silent; a matching error is clear too."""
    import warnings

    from tests.adversarial.harness import Ran

    def warn(tmp: Path) -> object:
        warnings.warn("mask m.png marks 60% of the image border as object", UserWarning, stacklevel=1)
        return 1

    def printed(tmp: Path) -> object:
        return Ran("", "eigview: warning: mask m.png marks 60% of the image border as object\n")

    def fail(tmp: Path) -> object:
        raise ValueError("mask m.png marks 95% of the image border as object")

    pattern = r"mask m\.png marks \d+% of the image border"
    assert outcome(Case("py", warn, pattern, warns=True), tmp_path)[0] == "clear"
    assert outcome(Case("cli", printed, pattern, warns=True), tmp_path)[0] == "clear"
    assert outcome(Case("err", fail, pattern, warns=True), tmp_path)[0] == "clear"
    assert outcome(Case("none", lambda t: 1, pattern, warns=True), tmp_path)[0] == "silent"
    assert outcome(Case("other", warn, r"aspect ratio", warns=True), tmp_path)[0] == "silent"
    assert outcome(Case("plain", warn, pattern), tmp_path)[0] == "silent"  # a warning is no error
