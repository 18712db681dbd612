"""The examples use the package's public API only, so that they show how it is meant to be used
and keep working when its internals move.

A public name is one in ``torch_eigview.__all__`` or in the ``__all__`` of one of its
subpackages or top-level modules (``torch_eigview.evaluation``, ``torch_eigview.check``, …),
imported from there: not from a deeper module (``torch_eigview.evaluation.coil``), a
private one (a path segment starting with ``_``) or the commands (``torch_eigview.apps``).
Every ``.py`` under ``examples/`` is read with :mod:`ast`, these tests included.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1]
# Scripts known to break the rule, each with what must change; strict, so that the entry
# fails (and goes) once the script is mended.
PENDING: dict[str, str] = {}
SCRIPTS = [
    pytest.param(p, marks=pytest.mark.xfail(reason=PENDING[p.name], strict=True)) if p.name in PENDING else p
    for p in sorted(EXAMPLES.rglob("*.py"))
]


def _public(module: str) -> set[str]:
    return set(getattr(importlib.import_module(module), "__all__", ()))


def _is_unit(name: str) -> bool:
    """Whether ``torch_eigview.<name>`` is a public subpackage or top-level module."""
    if name.startswith("_") or name == "apps":
        return False
    try:
        importlib.import_module(f"torch_eigview.{name}")
    except ImportError:
        return False
    return True


def problem(module: str, names: list[str]) -> str | None:
    """What is wrong with importing ``names`` from ``module`` (``[]``: the module itself), or None."""
    parts = module.split(".")
    if parts[0] != "torch_eigview":
        return None
    if any(p.startswith("_") for p in parts):
        return f"{module} is private"
    if len(parts) > 1 and parts[1] == "apps":
        return f"{module} is the commands' (torch_eigview.apps), not the library's"
    if len(parts) > 2:
        return f"{module} is not a public module: import from {'.'.join(parts[:2])}"
    if len(parts) == 2 and not _is_unit(parts[1]):
        return f"{module} does not exist"
    public = _public(module)
    # From the package itself a subpackage may be imported by name too (``from torch_eigview import io``).
    missing = sorted(n for n in names if n not in public and not (len(parts) == 1 and _is_unit(n)))
    return f"{missing} not in {module}.__all__" if missing else None


def imports(path: Path) -> list[tuple[int, str, list[str]]]:
    """``(line, module, names)`` of every import in ``path`` (``names`` empty for ``import m``),
    and of every attribute read through the package's module (``torch_eigview.nn.unit_rows``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name, []) for a in node.names]
        elif isinstance(node, ast.Attribute):
            chain: list[str] = []
            inner: ast.expr = node
            while isinstance(inner, ast.Attribute):
                chain.insert(0, inner.attr)
                inner = inner.value
            if isinstance(inner, ast.Name) and inner.id == "torch_eigview":
                if chain[0] in _public("torch_eigview"):
                    found.append((node.lineno, "torch_eigview", chain[:1]))
                else:  # a subpackage, then one of its names
                    found.append((node.lineno, f"torch_eigview.{chain[0]}", chain[1:2]))
    return found


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: p.relative_to(EXAMPLES).as_posix())
def test_examples_import_public_names_only(path: Path) -> None:
    bad = [
        f"{path.relative_to(EXAMPLES)}:{line}: {why}"
        for line, module, names in imports(path)
        if (why := problem(module, names)) is not None
    ]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize(
    ("source", "wrong"),
    [
        ("from torch_eigview.evaluation.coil import CoilExperiment", "not a public module"),
        ("from torch_eigview.apps.demo import run_demo", "torch_eigview.apps"),
        ("from torch_eigview.decomposition._fitted import x", "private"),
        ("from torch_eigview.synthesis import seed_foreground", "not in torch_eigview.synthesis.__all__"),
        ("from torch_eigview import build_recognizer", "not in torch_eigview.__all__"),
        ("import torch_eigview.geometry.tvl1", "not a public module"),
        ("import torch_eigview\ntorch_eigview.apps.cli.main()", "torch_eigview.apps"),
        ("import torch_eigview\ntorch_eigview.nn.functional", "not in torch_eigview.nn.__all__"),
    ],
)
def test_the_rule_catches_private_imports(tmp_path: Path, source: str, wrong: str) -> None:
    path = tmp_path / "example.py"
    path.write_text(source + "\n", encoding="utf-8")
    reasons = [problem(module, names) for _, module, names in imports(path)]
    assert any(r is not None and wrong in r for r in reasons), reasons


@pytest.mark.parametrize(
    "source",
    [
        "from torch_eigview import CoilFolder, environment_info",
        "from torch_eigview.evaluation import CoilExperiment, score",
        "from torch_eigview.datasets import SyntheticScene",
        "import torch_eigview",
        "import torch_eigview.evaluation",
        "import torch_eigview\ntorch_eigview.evaluation.score\ntorch_eigview.CoilFolder.images",
        "from torch_eigview import io",
        "from record import table",
    ],
)
def test_the_rule_lets_public_imports_through(tmp_path: Path, source: str) -> None:
    path = tmp_path / "example.py"
    path.write_text(source + "\n", encoding="utf-8")
    assert [problem(module, names) for _, module, names in imports(path)] == [None] * len(imports(path))
