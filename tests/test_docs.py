"""The documentation site builds without a warning and covers the package, the examples and the README.

The build runs Sphinx in a fresh process (autodoc imports every documented module) into a
temporary folder, warnings as errors, exactly as ``python -m sphinx -W -b html docs OUT``.
"""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
# The subpackages and modules with an API page, docs/api/<name>.rst.
API_PAGES = (
    "geometry",
    "warp",
    "synthesis",
    "decomposition",
    "nn",
    "method",
    "evaluation",
    "scale",
    "io",
    "datasets",
    "sklearn",
    "config",
    "check",
)


def documented_names(inventory: Path) -> set[str]:
    """The Python object names in a Sphinx ``objects.inv`` (format version 2)."""
    raw = inventory.read_bytes()
    header_end = 0
    for _ in range(4):  # four text lines, then the zlib-compressed body
        header_end = raw.index(b"\n", header_end) + 1
    assert raw.startswith(b"# Sphinx inventory version 2"), raw[:40]
    body = zlib.decompress(raw[header_end:]).decode("utf-8")
    return {line.split(" ", 1)[0] for line in body.splitlines() if re.match(r"\S+ py:", line)}


def _all(page: str) -> list[str]:
    return list(getattr(importlib.import_module(f"torch_eigview.{page}"), "__all__", ()))


def test_every_subpackage_has_an_api_page() -> None:
    pages = {p.stem for p in (DOCS / "api").glob("*.rst")} - {"index"}
    assert pages == set(API_PAGES)
    index = (DOCS / "api" / "index.rst").read_text(encoding="utf-8")
    for name in API_PAGES:
        text = (DOCS / "api" / f"{name}.rst").read_text(encoding="utf-8")
        assert f".. automodule:: torch_eigview.{name}\n" in text, name
        assert f"\n   {name}\n" in index, f"docs/api/index.rst does not list {name}"


def test_every_example_is_shown() -> None:
    text = (DOCS / "examples.md").read_text(encoding="utf-8")
    shown = set(re.findall(r"^```\{literalinclude\} \.\./examples/(\S+\.py)$", text, flags=re.MULTILINE))
    assert shown == {p.name for p in (ROOT / "examples").glob("*.py")}


def test_result_pages_are_up_to_date() -> None:
    """docs/results.md and docs/benchmarks.md are what the records under examples/ and
    benchmarks/ give (``python docs/make_pages.py`` writes them)."""
    argv = [sys.executable, str(DOCS / "make_pages.py"), "--check"]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr or proc.stdout


def test_index_includes_readme_and_architecture() -> None:
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    assert "```{include} ../README.md" in index
    assert "\narchitecture\n" in index and "\napi/index\n" in index and "\nexamples\n" in index


@pytest.mark.slow
def test_build_without_warnings(tmp_path: Path) -> None:
    out = tmp_path / "html"
    argv = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html"]
    argv += ["-d", str(tmp_path / "doctrees"), str(DOCS), str(out)]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, f"sphinx -W failed:\n{proc.stderr}"
    assert proc.stderr.strip() == "", proc.stderr
    # Every public name of every documented subpackage has its entry.
    names = documented_names(out / "objects.inv")
    public = [f"torch_eigview.{page}.{name}" for page in API_PAGES for name in _all(page)]
    missing = [name for name in public if name not in names]
    assert not missing, f"public names not in the API reference: {missing}"
    # The README's tables, the architecture page and the examples are pages of the site.
    index = (out / "index.html").read_text(encoding="utf-8")
    assert "<table" in index and "COIL-20" in index
    results = (out / "results.html").read_text(encoding="utf-8")
    assert "<table" in results and "paper Fig. 4(b)" in results  # the generated results page
    assert "Import directions" in (out / "architecture.html").read_text(encoding="utf-8")
    examples = re.sub(r"<[^>]+>", "", (out / "examples.html").read_text(encoding="utf-8"))
    assert examples.count("def main(") == len(list((ROOT / "examples").glob("*.py")))
