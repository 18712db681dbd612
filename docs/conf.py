"""Sphinx configuration: the README, the architecture page, the examples and the API from docstrings.

Build with ``python -m sphinx -W -b html docs docs/_build/html`` (``tests/test_docs.py``
builds it the same way, warnings as errors).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from sphinx.application import Sphinx
from sphinx.pycode import ModuleAnalyzer

ROOT = Path(__file__).resolve().parents[1]
# autodoc imports the package from this checkout, not from an installed copy elsewhere.
sys.path.insert(0, str(ROOT))
os.environ.setdefault("OMP_NUM_THREADS", "1")

project = "torch_eigview"
author = "torch_eigview contributors"
copyright = "torch_eigview contributors"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build"]
root_doc = "index"

# The README links to its own sections ("#layout"): anchors for headings down to level 3.
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]

autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
# Signatures carry the annotations; the docstrings' Args already describe each one.
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False

html_theme = "alabaster"
html_title = "torch_eigview"


def _skip_member(app: Sphinx, what: str, name: str, obj: Any, skip: bool, options: Any) -> bool:
    """Which members autodoc leaves out, beyond its defaults.

    Members scikit-learn generates on our estimators (``set_fit_request``, …) are left out:
    scikit-learn documents them, and their docstrings cite its glossary, which this site
    lacks.
    """
    if getattr(obj, "__module__", "").startswith("sklearn."):
        return True
    return skip


def _data_docstring(app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]) -> None:
    """Gives a re-exported constant (``torch_eigview.warp.BLENDS``) its defining module's docstring.

    autodoc reads a constant's docstring (the string literal or ``#:`` comment after it)
    from the source of the module it documents, the subpackage's ``__init__``, which only
    imports it, and falls back to the docstring of the value's type (``tuple``'s); the
    docstring lies in the submodule that assigns it.
    """
    type_doc = (type(obj).__doc__ or "").strip().splitlines()
    if what != "data" or (lines and lines[0].strip() != (type_doc or [""])[0].strip()):
        return
    package, _, attr = name.rpartition(".")
    # The subpackage's own modules first, then the rest of the package (a constant one
    # subpackage re-exports from another, ``method.AROUND_SEEDS`` from ``geometry.angles``).
    for prefix in (package + ".", package.split(".")[0] + "."):
        for module_name, module in list(sys.modules.items()):
            if not module_name.startswith(prefix) or getattr(module, attr, None) is not obj:
                continue
            docs = ModuleAnalyzer.for_module(module_name).find_attr_docs().get(("", attr))
            if docs:
                lines[:] = docs
                return
    lines[:] = []  # no docstring of its own: the value alone, not tuple's help


def setup(app: Sphinx) -> None:
    app.connect("autodoc-skip-member", _skip_member)
    app.connect("autodoc-process-docstring", _data_docstring)
