"""Prints the outcome of every adversarial case and the tally: ``python -m tests.adversarial.tally``.

Each case runs in its own empty temporary folder; ``-v`` prints every message too; naming
modules (``test_fit_inputs``, ...) runs only theirs.
"""

from __future__ import annotations

import collections
import sys
import tempfile
import warnings
from pathlib import Path

from tests.adversarial import (
    test_api_inputs,
    test_api_inputs_2,
    test_api_inputs_3,
    test_cli_files,
    test_cli_inputs,
    test_evaluate_inputs,
    test_fit_inputs,
    test_manifest_inputs,
)
from tests.adversarial.harness import outcome


def main(argv: list[str]) -> int:
    warnings.simplefilter("ignore")
    counts: collections.Counter[str] = collections.Counter()
    modules = (
        test_cli_inputs,
        test_cli_files,
        test_api_inputs,
        test_fit_inputs,
        test_manifest_inputs,
        test_evaluate_inputs,
        test_api_inputs_2,
        test_api_inputs_3,
    )
    only = [m for m in modules if m.__name__.rsplit(".", 1)[1] in argv]  # e.g. test_fit_inputs
    for module in only or modules:
        for case in module.CASES:
            with tempfile.TemporaryDirectory() as tmp:
                kind, what = outcome(case, Path(tmp))
            counts[kind] += 1
            if kind != "clear" or "-v" in argv:
                print(f"{kind:9s} {case.id}: {what.strip()[:300]!r}")
    total = sum(counts.values())
    print(
        f"{total} cases: "
        + ", ".join(f"{counts[k]} {k}" for k in ("clear", "unhelpful", "hang", "silent", "lost"))
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
