"""The scaling figure of ``bench_scaling.py --png``: seconds and peak memory against size."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from torch_eigview.files import atomic_open

__all__ = ["plot_scaling"]


def plot_scaling(raw: dict[str, Any], path: Path) -> None:
    """Draws the ``by_size`` and ``by_objects`` rows of a scaling run into ``path`` (PNG).

    Args:
        raw: ``{"by_size": [...], "by_objects": [...]}``, rows of :func:`benchmarks._fit_case.measure`.
        path: the image to write.

    Raises:
        ImportError: matplotlib is not installed.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(10, 4.2), squeeze=False)
    for ax, part, xkey, xlabel in (
        (axs[0][0], "by_size", "size", "image side (pixels)"),
        (axs[0][1], "by_objects", "objects", "objects (41 views each)"),
    ):
        for kind in ("explicit", "exact", "randomized"):
            rows = [r for r in raw[part] if r["kind"] == kind]
            xs = [r[xkey] for r in rows]
            ax.loglog(xs, [max(r["peak_mib"], 0.1) for r in rows], "o-", label=f"{kind} peak MiB")
            ax.loglog(xs, [r["seconds"] for r in rows], "s--", label=f"{kind} s")
        ax.set(xlabel=xlabel, title=f"eigenspace scaling ({part.replace('_', ' ')})")
        ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_open(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
