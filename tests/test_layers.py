"""The package's layers: imports run one way only, and no private name crosses a subpackage.

Every ``import`` in the package, module level or inside a function, is read with ``ast``
(nothing is imported). Each subpackage may import only the layers listed for it below;
``docs/architecture.md`` draws the same table.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "torch_eigview"

# unit -> the units it may import (besides itself). "base" is errors.py, check.py, lazy.py,
# files.py, environment.py and _tuning.py.
ALLOWED: dict[str, set[str]] = {
    "base": set(),
    "geometry": {"base"},
    "warp": {"base", "geometry"},
    "synthesis": {"base", "geometry", "warp"},
    "nn": {"base"},
    "decomposition": {"base", "nn"},
    "scale": {"base", "geometry", "warp", "synthesis", "nn", "decomposition"},
    "io": {"base", "nn"},
    "datasets": {"base", "geometry", "io"},
    "method": {"base", "geometry", "warp", "synthesis", "nn", "decomposition", "scale", "io", "datasets"},
    "sklearn": {"base", "geometry", "warp", "synthesis", "nn", "decomposition", "method"},
    "evaluation": {
        "base",
        "geometry",
        "warp",
        "synthesis",
        "nn",
        "decomposition",
        "scale",
        "io",
        "datasets",
        "method",
    },
    "apps": {
        "base",
        "evaluation",
        "geometry",
        "warp",
        "synthesis",
        "nn",
        "decomposition",
        "scale",
        "io",
        "datasets",
        "method",
    },
    "root": set(),  # the package's __init__ and __main__ import lazily or the command only
}


def _unit(module: str) -> str:
    """'torch_eigview.warp.operator' -> 'warp'; errors, check, lazy, files, environment,
    config, parse and _tuning are the base layer. ``_tuning`` is private to the package, not to a subpackage:
    every layer imports it as a module (``import torch_eigview._tuning as _tuning``) and
    reads its values at call time, so that a test can patch them."""
    parts = module.split(".")
    if len(parts) == 1:
        return "root"
    head = parts[1]
    if head in ("errors", "check", "lazy", "files", "environment", "config", "parse", "_tuning"):
        return "base"
    if head in ("__init__", "__main__"):
        return "root"
    return head


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[int, str, list[str]]]:
    """(line, imported module, imported names) for every torch_eigview import in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.split(".")[0] == "torch_eigview":
                found.append((node.lineno, node.module, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "torch_eigview":
                    found.append((node.lineno, alias.name, []))
    return found


MODULES = sorted(p for p in PACKAGE.rglob("*.py"))


def test_no_relative_imports() -> None:
    bad = [
        f"{p.relative_to(PACKAGE)}:{n.lineno}"
        for p in MODULES
        for n in ast.walk(ast.parse(p.read_text(encoding="utf-8")))
        if isinstance(n, ast.ImportFrom) and n.level
    ]
    assert not bad, f"relative imports (the layer check reads absolute ones): {bad}"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_run_down_the_layers(path: Path) -> None:
    here = _module_name(path)
    unit = _unit(here)
    if unit == "root":
        return
    wrong = [
        f"line {line}: {module} ({_unit(module)})"
        for line, module, _ in _imports(path)
        if _unit(module) != unit and _unit(module) not in ALLOWED[unit]
    ]
    assert not wrong, f"{here} ({unit}) may import only {sorted(ALLOWED[unit])}; it imports {wrong}"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_private_name_crosses_a_subpackage(path: Path) -> None:
    here = _module_name(path)
    unit = _unit(here)
    wrong = [
        f"line {line}: {module}.{name}"
        for line, module, names in _imports(path)
        for name in names
        if _unit(module) != unit
        and (name.startswith("_") or any(p.startswith("_") for p in module.split(".")))
    ]
    assert not wrong, f"{here} imports private names of another subpackage: {wrong}"


def test_the_table_names_every_subpackage() -> None:
    units = {_unit(_module_name(p)) for p in MODULES}
    assert units <= set(ALLOWED), f"subpackages without a layer: {units - set(ALLOWED)}"


def test_the_architecture_page_draws_this_table() -> None:
    """docs/architecture.md's import table is this one: the page stays true."""
    page = (PACKAGE.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    block = page.split("```python\n", 1)[1].split("```", 1)[0]
    drawn = ast.literal_eval(block.split("=", 1)[1].strip())
    assert drawn == ALLOWED


def _reads_environment(node: ast.AST) -> bool:
    if isinstance(node, ast.Attribute):
        return node.attr in ("environ", "environb", "getenv")
    return isinstance(node, ast.Name) and node.id in ("environ", "getenv")


def test_only_the_command_and_the_data_home_read_the_environment() -> None:
    """Process policy stays out of the library: limits are parameters and configuration;
    the command line reads EIGVIEW_MAX_*, and the data home TORCH_EIGVIEW_DATA."""
    allowed = {
        ("apps/cli.py", "limits_from_environment"),
        ("apps/cli.py", "ranks_from_environment"),  # torchrun's RANK and WORLD_SIZE
        ("datasets/coil.py", "_data_home"),
    }
    found = set()
    for path in PACKAGE.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        name = path.relative_to(PACKAGE).as_posix()
        inside: set[int] = set()
        for func in ast.walk(tree):
            if isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for node in ast.walk(func):
                    if id(node) not in inside and _reads_environment(node):
                        found.add((name, func.name))
                    inside.add(id(node))
        if any(_reads_environment(n) and id(n) not in inside for n in ast.walk(tree)):
            found.add((name, "<module>"))
    assert found <= allowed, f"environment read outside the command and the data home: {found - allowed}"
