"""Prints the outcome of every adversarial case and the tally: ``python -m tests.adversarial.tally``.

Each case runs in its own empty temporary folder: the bad inputs (``CASES`` of each module,
judged clear, unhelpful, hang, silent or lost), then the good ones (``GOOD``, judged right
or wrong). Every case that is not clear or right is printed as ``module/id``, marked
``(todo)`` where the package's message is known not to say the cause yet (the case's
``todo``); ``-v`` prints every message too; naming modules (``test_fit_inputs``, ...) runs
only theirs.
"""

from __future__ import annotations

import collections
import sys
import tempfile
import warnings
from pathlib import Path
from types import ModuleType

from tests.adversarial import (
    test_api_inputs,
    test_api_inputs_2,
    test_api_inputs_3,
    test_cli_files,
    test_cli_inputs,
    test_evaluate_inputs,
    test_fit_inputs,
    test_manifest_inputs,
    test_wrong_inputs,
)
from tests.adversarial.harness import judge, outcome


def _name(module: ModuleType) -> str:
    return module.__name__.rsplit(".", 1)[1]


def main(argv: list[str]) -> int:
    warnings.simplefilter("ignore")
    counts: collections.Counter[str] = collections.Counter()
    good: collections.Counter[str] = collections.Counter()
    modules = (
        test_cli_inputs,
        test_cli_files,
        test_api_inputs,
        test_fit_inputs,
        test_manifest_inputs,
        test_evaluate_inputs,
        test_api_inputs_2,
        test_api_inputs_3,
        test_wrong_inputs,
    )
    only = [m for m in modules if _name(m) in argv]  # e.g. test_fit_inputs
    for module in only or modules:
        for case in module.CASES:
            with tempfile.TemporaryDirectory() as tmp:
                kind, what = outcome(case, Path(tmp))
            counts[kind] += 1
            if kind != "clear" or "-v" in argv:
                known = " (todo)" if case.todo else ""  # a message the package is to reword
                print(f"{kind:9s} {_name(module)}/{case.id}{known}: {what.strip()[:300]!r}")
    for module in only or modules:
        for case in module.GOOD:
            with tempfile.TemporaryDirectory() as tmp:
                kind, what = judge(case, Path(tmp))
            good[kind] += 1
            if kind != "right" or "-v" in argv:
                print(f"{kind:9s} {_name(module)}/{case.id}: {what.strip()[:300]!r}")
    total = sum(counts.values())
    print(
        f"{total} cases: "
        + ", ".join(f"{counts[k]} {k}" for k in ("clear", "unhelpful", "hang", "silent", "lost"))
    )
    print(f"{sum(good.values())} good cases: {good['right']} right, {good['wrong']} wrong")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
