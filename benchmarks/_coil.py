"""Where the benchmarks find COIL-20: ``--root``, else ``$TORCH_EIGVIEW_DATA/coil-20-proc``,
else ``../shared/data/coil-20-proc`` beside the checkout.

The library itself never looks beside the source checkout (its default data home is the
user's); the benchmarks run from the checkout, where the project keeps its data sets.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from torch_eigview.datasets import DATA_ENV

__all__ = ["coil_root", "data_home", "default_coil_root"]

CHECKOUT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def data_home() -> Path:
    """``$TORCH_EIGVIEW_DATA`` when set (and not empty), else ``../shared/data`` beside the checkout."""
    env = os.environ.get(DATA_ENV, "")
    return Path(env).expanduser() if env else CHECKOUT_DATA


def default_coil_root() -> Path:
    """The COIL-20 folder when ``--root`` is not given (it need not exist)."""
    return data_home() / "coil-20-proc"


def coil_root(p: argparse.ArgumentParser, root: str | None) -> Path:
    """The COIL-20 folder of ``--root``, or the default one; a missing folder exits 2 with a
    message that names it and the ways to point at the images, not with a traceback."""
    path = Path(root) if root is not None else default_coil_root()
    if not path.is_dir():
        source = (
            "given with --root"
            if root is not None
            else f"the default; {DATA_ENV}={os.environ.get(DATA_ENV, '')!r}"
        )
        p.error(
            f"COIL-20 images not found: {str(path)!r} ({source}) must be an existing directory of "
            f"obj{{O}}__{{P}}.png images. Put coil-20-proc/ in {data_home()}, or set {DATA_ENV} to the "
            "folder that holds it, or give the folder itself with --root DIR."
        )
    return path
