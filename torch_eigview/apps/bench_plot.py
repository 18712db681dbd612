"""The figure of the benchmarks (``python -m torch_eigview.apps.bench --png FILE``)."""

from __future__ import annotations

from typing import Any

from torch_eigview.files import atomic_open
from torch_eigview.lazy import require

__all__ = ["plot_results"]


def plot_results(results: dict[str, Any], path: str) -> None:
    """Draws the warp timings and the scaling figures of a benchmark record into ``path`` (PNG).

    Args:
        results: the record :func:`torch_eigview.apps.bench.main` writes as JSON; its
            ``"warp"`` and ``"scaling"`` sections are drawn, one panel each (two for scaling).
        path: the image to write.

    Raises:
        ImportError: matplotlib is not installed (the message names the ``[plot]`` extra).
    """
    matplotlib = require("matplotlib", "plot", "the benchmark figure (--png)")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (["warp"] if "warp" in results else []) + (
        ["by_size", "by_objects"] if "scaling" in results else []
    )
    if not panels:
        return
    fig, axs = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4.2), squeeze=False)
    axes = dict(zip(panels, axs[0], strict=True))
    if "warp" in results:
        w = results["warp"]
        ax = axes["warp"]
        for key, label in (
            ("kornia_s", "kornia remap"),
            ("sparse_views_s", "sparse G·C"),
            ("skimage_loop_s", "skimage loop"),
        ):
            rows = [r for r in w if key in r]
            ax.loglog([r["size"] ** 2 for r in rows], [r[key] for r in rows], "o-", label=label)
        ax.set(xlabel="pixels per view", ylabel="seconds", title=f"warp {w[0]['views']} views")
        ax.legend()
    if "scaling" in results:
        for ax, part, xkey, xlabel in (
            (axes["by_size"], "by_size", "size", "image side (pixels)"),
            (axes["by_objects"], "by_objects", "objects", "objects (41 views each)"),
        ):
            rows = results["scaling"][part]
            for kind in ("explicit", "exact", "randomized"):
                sel = [r for r in rows if r["kind"] == kind]
                ax.loglog(
                    [r[xkey] for r in sel],
                    [max(r["peak_mib"], 0.1) for r in sel],
                    "o-",
                    label=f"{kind} peak MiB",
                )
                ax.loglog([r[xkey] for r in sel], [r["seconds"] for r in sel], "s--", label=f"{kind} s")
            ax.set(xlabel=xlabel, title=f"eigenspace scaling ({part.replace('_', ' ')})")
            ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_open(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
