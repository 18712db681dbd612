"""The correspondence stage alone: each flow's disparities between two seed views α apart
against the motion chained through the real views between them.

A turntable data set holds the real views between the seeds (COIL-20: every 5°). TV-L1
between consecutive real views follows their small motion well; composed from the first
seed to the second, these flows give a reference disparity that no seed-pair method can
see (it uses the test views, so it is for diagnosis only). It is rough: each link adds
its own error (on rendered shapes, against the exact disparity, a median of 0.4–0.9 px
after six to nine links), but it does not lose large motions as one flow between the
ends does. Over the first seed's foreground, per pair:

- ``slope``: the least-squares factor s of ``disparity ≈ s · reference`` (1: the whole
  motion found; near 0: the flow found almost none of it), the median over pairs;
- ``error``: the median absolute difference in pixels, the mean over pairs;
- ``trusted``: the share of the foreground that passes the forward–backward check.

``python -m torch_eigview.apps.diagnose correspondence --root DIR [--flow-alphas 10 45]``
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.synthesis import SynthesisOptions
from torch_eigview.warp.normalize import foreground_mask

__all__ = ["FLOWS", "chained_disparity", "correspondence_table"]

#: The flows the table compares.
FLOWS = ("tvl1", "rows", "guided")


def chained_disparity(views: torch.Tensor) -> torch.Tensor:
    """(H, W) horizontal motion from the first of ``views`` (V, C, H, W) to the last, TV-L1
    between consecutive views composed along the way (bilinear, border padding)."""
    from torch_eigview.geometry.tvl1 import tvl1_flow, warp_by_flow

    gray = views.mean(dim=1).float()
    total = gray.new_zeros(1, 2, *gray.shape[-2:])  # rows first, as a flow
    for flow in tvl1_flow(gray[:-1], gray[1:]):  # (V - 1, 2, H, W)
        total = total + warp_by_flow(flow[None], total)
    return total[0, 1]


def correspondence_table(
    folder: CoilFolder,
    objects: Sequence[int],
    centers: Sequence[float],
    alphas: Sequence[float],
    step: float = 5.0,
    flows: Sequence[str] = FLOWS,
) -> str:
    """The table (see the module's docstring) for seed pairs at each center and α."""
    if not objects or not centers or not alphas:
        raise ValueError(
            f"objects, centers and alphas must each name at least one, got {list(objects)}, "
            f"{list(centers)}, {list(alphas)}"
        )
    lines = [
        "seed-pair disparity against the motion chained through the real views between the seeds",
        f"{'alpha':>6} {'flow':>8} {'slope':>7} {'error px':>9} {'trusted':>8}",
    ]
    for alpha in alphas:
        n_steps = round(alpha / step)
        if n_steps < 1 or abs(n_steps * step - alpha) > 1e-6:
            raise ValueError(f"alpha={alpha:g} must be a positive multiple of the poses' step {step:g}")
        stats: dict[str, list[tuple[float, float, float]]] = {f: [] for f in flows}
        for obj in objects:
            for c in centers:
                views = folder.images(obj, [c + i * step for i in range(n_steps + 1)])
                reference = chained_disparity(views)
                fg = foreground_mask(views[:1], SynthesisOptions().background)[0]
                ref = reference[fg].double()
                for flow in flows:
                    # The flow as the synthesis runs it, without the elevation fit.
                    opts = SynthesisOptions(flow=flow)
                    corr = estimate_correspondence(
                        views[:1],
                        views[-1:],
                        method=flow,
                        threshold=opts.threshold,
                        **opts.flow_kwargs(alpha),
                    )
                    d = corr.disparity_12[0][fg].double()
                    slope = float((d * ref).sum() / (ref * ref).sum().clamp_min(1e-12))
                    error = float((d - ref).abs().median())
                    stats[flow].append((slope, error, float(corr.valid_12[0][fg].double().mean())))
        for flow in flows:
            t = torch.tensor(stats[flow], dtype=torch.float64)
            lines.append(
                f"{alpha:6g} {flow:>8} {float(t[:, 0].median()):7.2f} {float(t[:, 1].mean()):9.2f} "
                f"{float(t[:, 2].mean()):8.2f}"
            )
    return "\n".join(lines)
