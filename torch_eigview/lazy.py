"""Lazy imports: public names (PEP 562) and the modules of the optional extras.

``import torch_eigview`` and ``import torch_eigview.io`` import nothing heavy: a name is
imported from its submodule on first use and cached in the package's namespace. The
optional dependencies (``[onnx]``, ``[plot]``, ``[sklearn]``) are imported where they are
used, through :func:`require`, which names the extra to install when one is missing. This
module imports no torch, so the torch-free parts (``eigview predict``) stay light.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping, Sequence
from types import ModuleType
from typing import Any

__all__ = ["attach", "require"]


def require(module: str, extra: str, purpose: str) -> ModuleType:
    """Imports an optional dependency, or says which extra installs it.

    Args:
        module: the module to import, e.g. ``"onnxruntime"``.
        extra: the ``torch_eigview`` extra that installs it, e.g. ``"onnx"``.
        purpose: what needs it, for the message, e.g. ``"eigview predict"``.

    Returns:
        The imported module.

    Raises:
        ImportError: ``module`` is not installed (or fails to import); the message names
            the ``pip install`` to run.

    Example:
        >>> require("json", "onnx", "reading metadata").__name__
        'json'
    """
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ImportError(
            f"{purpose} needs {module}, which is not installed: pip install 'torch_eigview[{extra}]'",
            name=module,
        ) from err


def attach(
    package: str, sources: Mapping[str, str], public: Sequence[str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` of a package with lazily imported names.

    Args:
        package: the package's ``__name__``.
        sources: public name -> the submodule (relative to ``package``) that defines it.
        public: the package's ``__all__``.

    Example:
        >>> getattr_, dir_ = attach("json", {"JSONDecoder": "decoder"}, ["JSONDecoder"])
        >>> getattr_("JSONDecoder").__name__
        'JSONDecoder'
    """

    def __getattr__(name: str) -> Any:
        source = sources.get(name)
        if source is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{source}"), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(public))

    return __getattr__, __dir__
