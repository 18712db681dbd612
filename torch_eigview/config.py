"""The limits on how much work one argument may ask for, as a configuration.

A range of angles with a tiny step, an image side of a million pixels or a list of a
billion object ids would fill the memory long before any error; the public functions
check such requests against these limits first and name the argument that asked. The
defaults suit every data set this library was built for; a caller that means more raises
a limit for a block of code, as scikit-learn's ``config_context`` does::

    with torch_eigview.config_context(max_views=7200):
        est.fit(seeds, angles)  # synthesizes up to 7200 views per object

The ``eigview`` command reads the environment variables ``EIGVIEW_MAX_VIEWS``,
``EIGVIEW_MAX_IMAGE_SIDE``, ``EIGVIEW_MAX_OBJECTS``, ``EIGVIEW_MAX_THREADS`` and
``EIGVIEW_MAX_MODEL_BYTES`` into this configuration; the library itself reads none.
This module imports nothing heavy (``eigview predict`` runs without torch).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from types import MappingProxyType
from typing import Any

__all__ = ["DEFAULTS", "check_limit", "config_context", "get_config", "set_config"]

#: The limits and their defaults.
#:
#: - ``max_views``: views per object one range of angles may hold (every 0.1 degree round
#:   the circle);
#: - ``max_image_side``: pixels per side of an image a view is resized to (a view is held
#:   as H × W floats per channel, many times over);
#: - ``max_objects``: object ids one selection may name;
#: - ``max_threads``: intra-op threads one ``threads(n)`` may ask for (each a stack and a
#:   pool slot);
#: - ``max_model_bytes``: bytes an ONNX model may take in memory, with its batch of inputs
#:   (2 GiB).
DEFAULTS = MappingProxyType(
    {
        "max_views": 3600,
        "max_image_side": 512,
        "max_objects": 100_000,
        "max_threads": 1024,
        "max_model_bytes": 2 << 30,
    }
)

_CONFIG: ContextVar[MappingProxyType[str, int]] = ContextVar("torch_eigview_config", default=DEFAULTS)


def get_config() -> dict[str, int]:
    """The limits in force (a copy).

    Example:
        >>> get_config()["max_views"]
        3600
    """
    return dict(_CONFIG.get())


def _checked(limits: dict[str, Any]) -> dict[str, int]:
    unknown = sorted(set(limits) - set(DEFAULTS))
    if unknown:
        raise TypeError(f"unknown limit(s) {unknown}; the limits are {sorted(DEFAULTS)}")
    for key, value in limits.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{key} must be a positive int, got {value!r}")
    return limits


def set_config(**limits: int) -> None:
    """Sets limits for the rest of this context (thread or task), e.g. ``max_views=7200``.

    Raises:
        TypeError: an unknown limit.
        ValueError: a value that is not a positive int.
    """
    _CONFIG.set(MappingProxyType({**_CONFIG.get(), **_checked(limits)}))


@contextmanager
def config_context(**limits: int) -> Iterator[dict[str, int]]:
    """Sets limits inside a ``with`` block and restores the previous ones on exit.

    Yields:
        The limits in force inside the block.

    Example:
        >>> with config_context(max_views=10) as config:
        ...     config["max_views"]
        10
        >>> get_config()["max_views"]
        3600
    """
    token = _CONFIG.set(MappingProxyType({**_CONFIG.get(), **_checked(limits)}))
    try:
        yield get_config()
    finally:
        _CONFIG.reset(token)


def check_limit(count: float, name: str, what: str, key: str) -> None:
    """Raises ValueError when ``count`` ``what`` (asked for by argument ``name``) exceed the
    limit ``key``; the message says the limit and how to raise it.

    Example:
        >>> check_limit(10, "synth", "views per object", "max_views")
        >>> check_limit(1e9, "synth", "views per object", "max_views")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: synth asks for 1e+09 views per object, more than the limit of 3600 (max_views); ...
    """
    bound = _CONFIG.get()[key]
    if not count <= bound:  # NaN counts as over the limit
        env = f"EIGVIEW_{key.upper()}"
        raise ValueError(
            f"{name} asks for {count:.6g} {what}, more than the limit of {bound} ({key}); raise it with "
            f"torch_eigview.config_context({key}=...), or for the eigview command the environment variable {env}"
        )
