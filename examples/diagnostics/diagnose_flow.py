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

Run: ``python examples/diagnostics/diagnose_flow.py [--root DIR] [--alphas 10 45]``
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from diagnostic_record import (
    add_centers_flag,
    add_objects_flag,
    add_record_flag,
    add_root_flag,
    check_record,
    coil_folder,
    command_line,
    table,
    text,
    write_record,
)

from torch_eigview import CoilFolder, SynthesisOptions, estimate_correspondence
from torch_eigview.scale import threads
from torch_eigview.warp import foreground_mask

#: The flows the table compares.
FLOWS = ("tvl1", "rows", "guided")


def compose(fields: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """(N, F, H, W) ``fields`` sampled bilinearly at (r + flow[:, 0], c + flow[:, 1]) of a
    (N, 2, H, W) flow (rows first), edge values outside (pixel coordinates)."""
    h, w = fields.shape[-2:]
    rows = torch.arange(h, dtype=flow.dtype, device=flow.device).view(h, 1)
    cols = torch.arange(w, dtype=flow.dtype, device=flow.device)
    gx = (flow[:, 1] + cols) * (2.0 / max(w - 1, 1)) - 1
    gy = (flow[:, 0] + rows) * (2.0 / max(h - 1, 1)) - 1
    grid = torch.stack([gx, gy], dim=-1)
    return F.grid_sample(fields, grid, mode="bilinear", padding_mode="border", align_corners=True)


def chained_disparity(views: torch.Tensor) -> torch.Tensor:
    """(H, W) horizontal motion from the first of ``views`` (V, C, H, W) to the last: TV-L1
    between consecutive views (scikit-image's settings), composed along the way."""
    h, w = views.shape[-2:]
    total = views.new_zeros(1, 2, h, w, dtype=torch.float32)  # rows first, as a flow
    if views.shape[0] < 2:
        return total[0, 1]
    corr = estimate_correspondence(views[:-1], views[1:], method="tvl1")
    for flow in torch.stack([corr.vertical_12, corr.disparity_12], 1).float():  # (V - 1, 2, H, W)
        total = total + compose(flow[None], total)
    return total[0, 1]


def correspondence_rows(
    folder: CoilFolder,
    objects: Sequence[int],
    centers: Sequence[float],
    alphas: Sequence[float],
    step: float = 5.0,
    flows: Sequence[str] = FLOWS,
) -> list[list[object]]:
    """Per α and flow ``[alpha, flow, slope, error px, trusted]`` (see the module's docstring)
    over the seed pairs at each center."""
    if not objects or not centers or not alphas:
        raise ValueError(
            f"objects, centers and alphas must each name at least one, got {list(objects)}, "
            f"{list(centers)}, {list(alphas)}"
        )
    for alpha in alphas:
        n_steps = round(alpha / step)
        if n_steps < 1 or abs(n_steps * step - alpha) > 1e-6:
            raise ValueError(f"alpha={alpha:g} must be a positive multiple of the poses' step {step:g}")
    rows: list[list[object]] = []
    for alpha in alphas:
        n_steps = round(alpha / step)
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
            rows.append([alpha, flow, float(t[:, 0].median()), float(t[:, 1].mean()), float(t[:, 2].mean())])
    return rows


def main(argv: list[str] | None = None) -> list[list[object]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_root_flag(parser)
    add_objects_flag(parser)
    add_centers_flag(parser)
    parser.add_argument("--alphas", type=float, nargs="+", default=[10.0, 45.0], help="seed angles, degrees")
    parser.add_argument("--flows", nargs="+", choices=FLOWS, default=list(FLOWS))
    add_record_flag(parser, "diagnose_flow")
    args = parser.parse_args(argv)
    check_record(parser, args.record)
    folder = coil_folder(parser, args.root)
    objects = list(args.objects or folder.objects)
    try:  # an angle off the pose grid: one line naming it
        rows = correspondence_rows(folder, objects, args.centers, args.alphas, flows=args.flows)
    except ValueError as exc:
        parser.error(str(exc))
    tab = table(
        f"Seed-pair disparity against the motion chained through the real views between the seeds "
        f"({len(objects)} objects × centers {', '.join(f'{c:g}' for c in args.centers)}): slope 1 is the "
        "whole motion found, error the median absolute difference in pixels, trusted the share of the "
        "foreground that passes the forward–backward check.",
        ["α", "flow", "slope", "median error (px)", "trusted"],
        rows,
    )
    print(text(tab))
    write_record(
        args.record,
        title="Diagnosis: the correspondences against the chained real motion",
        command=command_line(__file__, argv),
        tables=[tab],
    )
    return rows


if __name__ == "__main__":
    with threads():  # the commands' thread policy: one intra-op thread, idle CPUs for the eigen step
        main()
