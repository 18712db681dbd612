"""Fixtures of the examples' tests: the scripts' folders on the import path, one torch
thread, and COIL-20.

``python -m pytest -q examples`` collects these tests. The scripts of ``examples/paper``
and ``examples/diagnostics`` import their sibling helpers by name, as they do when run
(``python examples/paper/camera_models.py`` puts its own folder first on the path), so
both folders go on the path here. The COIL-20 images are found as the tests of the
package find them (``tests/conftest.py``): ``$TORCH_EIGVIEW_DATA/coil-20-proc``, else
``../shared/data/coil-20-proc`` beside the checkout; a test that needs them skips, naming
where it looked, when they are absent.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
import torch

from torch_eigview import CoilFolder
from torch_eigview.datasets import DATA_ENV

EXAMPLES = Path(__file__).resolve().parents[1]
for folder in ("paper", "diagnostics"):
    if str(EXAMPLES / folder) not in sys.path:
        sys.path.insert(0, str(EXAMPLES / folder))

# One intra-op thread, as the commands run by default: the scripts' worker threads then
# do not oversubscribe the cores, whose spinning threads slow a shared machine manyfold.
torch.set_num_threads(1)


@pytest.fixture(scope="session")
def coil_root() -> Path:
    """The processed COIL-20 images; skips when absent."""
    env = os.environ.get(DATA_ENV, "")
    data = Path(env).expanduser() if env else EXAMPLES.parents[1] / "shared" / "data"
    root = data / "coil-20-proc"
    if not root.is_dir():
        where = f"{DATA_ENV}={env}" if env else f"../shared/data ({DATA_ENV} unset)"
        pytest.skip(f"COIL-20 not found at {root}: no coil-20-proc in {where}")
    return root


@pytest.fixture(scope="session")
def folder(coil_root: Path) -> CoilFolder:
    """A :class:`~torch_eigview.CoilFolder` over ``coil_root`` (its image cache shared by the session)."""
    return CoilFolder(coil_root)
