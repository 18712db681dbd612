"""Fixtures of the benchmarks' tests (``python -m pytest -q benchmarks``): one thread, the COIL-20 folder."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from benchmarks._coil import default_coil_root
from torch_eigview.datasets import DATA_ENV
from torch_eigview.scale import threads


@pytest.fixture(autouse=True)
def one_thread() -> Iterator[None]:
    """Every test on one torch thread, as the eigview commands run: on a machine that other
    work keeps busy a second thread waits at every barrier, and a small run takes several
    times longer (the tests check that the benchmarks work, not how fast)."""
    with threads(1):
        yield


@pytest.fixture(scope="session")
def coil_root() -> Path:
    """The processed COIL-20 images, found as the scripts find them (``$TORCH_EIGVIEW_DATA``,
    else ``../shared/data`` beside the checkout); skips when absent."""
    root = default_coil_root()
    if not root.is_dir():
        env = os.environ.get(DATA_ENV, "")
        where = f"{DATA_ENV}={env}" if env else f"../shared/data ({DATA_ENV} unset)"
        pytest.skip(f"COIL-20 not found at {root}: no coil-20-proc in {where}")
    return root
