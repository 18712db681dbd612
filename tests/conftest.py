"""Shared fixtures: devices, dtypes with their tolerances, and the COIL-20 folder.

Test files may define a local ``dtype`` or ``device`` fixture (or parametrize those names);
pytest then uses the local one, so these are defaults, not requirements.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from torch_eigview import CoilFolder
from torch_eigview.datasets.coil import DATA_ENV

# One tolerance per dtype: float32 keeps about 7 digits, float64 about 16; the warp and the
# camera model lose a few digits to trigonometry and bilinear weights, not more.
TOL: dict[torch.dtype, dict[str, float]] = {
    torch.float32: dict(atol=1e-5, rtol=1e-5),
    torch.float64: dict(atol=1e-10, rtol=1e-10),
}

_CUDA = torch.cuda.is_available()

# Under pytest-xdist (``-n 2``: the README's test command) each worker process runs one
# torch thread: two workers of two OpenMP threads each would oversubscribe two cores, and
# their threads spin while they wait for each other. A test that needs more sets them
# itself (``threads(n)``).
if os.environ.get("PYTEST_XDIST_WORKER"):
    torch.set_num_threads(1)


@pytest.fixture(
    params=["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not _CUDA, reason="CUDA not available"))]
)
def device(request: pytest.FixtureRequest) -> torch.device:
    """Every test that takes ``device`` runs on the CPU, and on CUDA where there is one."""
    return torch.device(request.param)


@pytest.fixture(params=[torch.float32, torch.float64], ids=["float32", "float64"])
def dtype(request: pytest.FixtureRequest) -> torch.dtype:
    return request.param


@pytest.fixture
def tol(dtype: torch.dtype) -> dict[str, float]:
    """``atol``/``rtol`` for ``torch.testing.assert_close`` at the current ``dtype``."""
    return TOL[dtype]


@pytest.fixture(scope="session")
def coil_root() -> Path:
    """The processed COIL-20 images: ``$TORCH_EIGVIEW_DATA/coil-20-proc`` where that variable
    is set (as the commands read it; a machine the checkout's ``../shared`` does not reach),
    else ``../shared/data/coil-20-proc`` beside the checkout; skips when absent."""
    env = os.environ.get(DATA_ENV, "")
    data = Path(env).expanduser() if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"
    root = data / "coil-20-proc"
    if not root.is_dir():
        where = f"{DATA_ENV}={env}" if env else f"../shared/data ({DATA_ENV} unset)"
        pytest.skip(f"COIL-20 not found at {root}: no coil-20-proc in {where}")
    return root


@pytest.fixture(scope="session")
def folder(coil_root: Path) -> CoilFolder:
    """A :class:`CoilFolder` over ``coil_root`` (its image cache shared by the session)."""
    return CoilFolder(coil_root)
