"""The build on a CUDA device: views synthesized per second, and the COIL-100-sized build end to end against the CPU's.

On random smooth views of 100 objects (10 with ``--quick``) × 41 views × 3 × 128 × 128,
two seeds 5 px apart each:

- *maps + warp*: views per second of ``NovelViewWarp.maps`` and ``apply_maps`` for all
  objects at all 41 angles in one batch;
- *build*: the correspondence (the default guided flow: the row matcher and TV-L1, every
  object's pair and both directions in one batch, on the device), synthesis and the
  eigenspace (k = 15), on the GPU and on the CPU (the reference of the ratio), with the
  largest principal angle between the two eigenspaces.

Without a GPU it says "not measured: no GPU" and runs the same code on the CPU at a small
size (3 objects of 64 × 64), so that the one command is known to work (``.ci/gpu --cpu``).
Run from the repository root:

``python benchmarks/bench_cuda.py [--quick] [--threads N] [--out FILE]``
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_cuda.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import torch

from benchmarks._record import (
    add_threads,
    check_out,
    command_line,
    format_table,
    parser,
    record_path,
    table,
    write_record,
)
from benchmarks._timing import clock
from benchmarks._views import smooth_views
from torch_eigview import Eigenspace, NovelViewWarp, SynthesisOptions, synthesize_views
from torch_eigview.geometry import correspondence_from_disparity
from torch_eigview.scale import threads
from torch_eigview.synthesis import object_geometries

THETAS = list(range(-20, 21))
TARGET_S = 3.0  # the GPU build of 100 objects
TARGET_RAD = 1e-4  # its largest principal angle to the CPU build's eigenspace


def warp_rate(device: torch.device, n_objects: int, size: int, repeats: int = 3) -> float:
    """Views per second of maps + warp for ``n_objects`` objects × 41 angles in one batch."""
    ramp = torch.sin(torch.linspace(0, math.pi, size))[None, :].expand(size, size)
    disp = torch.stack([-(1.0 + 0.1 * o) * ramp for o in range(n_objects)]).to(device)
    corr = correspondence_from_disparity(disp)
    seeds = torch.stack([smooth_views(o, 6, 3, size)[[0, 5]] for o in range(n_objects)], 1).to(device)
    warp = NovelViewWarp(5.0, elevation=10.0)
    best = math.inf
    for _ in range(repeats + 1):  # the first call warms up
        t0 = clock(device)
        warp.apply_maps(warp.maps(corr, THETAS), seeds)
        best = min(best, clock(device) - t0)
    return n_objects * len(THETAS) / best


def build(device: torch.device, n_objects: int, size: int) -> tuple[float, torch.Tensor]:
    """The build end to end on ``device``: (seconds, (15, N) float64 components on the CPU)."""
    seeds = [smooth_views(o, 6, 3, size)[[0, 5]].to(device) for o in range(n_objects)]
    options = SynthesisOptions()
    t0 = clock(device)
    geometry = object_geometries(seeds, 5.0, options)
    views = [synthesize_views(s, 5.0, THETAS, options, g).views for s, g in zip(seeds, geometry, strict=True)]
    space = Eigenspace(15).fit(torch.cat(views).flatten(1))
    seconds = clock(device) - t0
    return seconds, space.components_.detach().to("cpu", torch.float64)


def principal_angle(a: torch.Tensor, b: torch.Tensor) -> float:
    """The largest principal angle (radians) between the row spaces of ``a`` and ``b``."""
    qa, qb = torch.linalg.qr(a.T).Q, torch.linalg.qr(b.T).Q
    return float(torch.arccos(torch.linalg.svdvals(qa.T @ qb).clamp(max=1.0).min()))


def bench_cuda(quick: bool) -> dict[str, Any]:
    """Views per second and the build on CUDA, with the CPU build's seconds and the principal
    angle to its eigenspace; without a GPU the CPU fallback at a small size."""
    if torch.cuda.is_available():
        device, n_objects, size = torch.device("cuda"), (10 if quick else 100), 128
    else:
        device, n_objects, size = torch.device("cpu"), 3, 64
    out: dict[str, Any] = {"device": str(device), "objects": n_objects, "size": size}
    if device.type == "cuda":
        out["device_name"] = torch.cuda.get_device_name(device)
    out["views_per_s"] = warp_rate(device, n_objects, size)
    out["build_s"], comps = build(device, n_objects, size)
    if device.type == "cuda":
        cpu_s, cpu_comps = build(torch.device("cpu"), n_objects, size)
        out["cpu_build_s"] = cpu_s
        out["angle_to_cpu_rad"] = principal_angle(comps, cpu_comps)
    return out


def report(c: dict[str, Any]) -> tuple[dict[str, Any], str]:
    """The record's table and a sentence on the targets (or on the missing GPU)."""
    what = f"{c['objects']} objects × 41 views × 3×{c['size']}×{c['size']}"
    cpu_s = c.get("cpu_build_s")
    t = table(
        f"Build of {what} end to end (guided flow, synthesis, eigenspace k = 15): seconds, "
        "ratio of the CPU build to it, largest principal angle to the CPU build's eigenspace",
        ["device", "maps + warp views/s", "build s", "CPU build s", "CPU / device", "angle to CPU (rad)"],
        [
            [
                c.get("device_name", c["device"]),
                c["views_per_s"],
                c["build_s"],
                cpu_s,
                cpu_s / c["build_s"] if cpu_s is not None else None,
                c.get("angle_to_cpu_rad"),
            ]
        ],
    )
    if c["device"] == "cpu":
        note = f"cuda: not measured: no GPU. CPU fallback of the same code ({what})."
    else:
        ok = c["objects"] == 100 and c["build_s"] < TARGET_S and c["angle_to_cpu_rad"] < TARGET_RAD
        note = (
            f"Target: under {TARGET_S:g} s for 100 objects and a principal angle below {TARGET_RAD:g} rad: "
            f"{'met' if ok else 'NOT met'}."
        )
    return t, note


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "10 objects on the GPU (the CPU fallback is small anyway)")
    add_threads(p)
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    with threads(args.threads):
        c = bench_cuda(args.quick)
    t, note = report(c)
    print(format_table(t), note, sep="\n")
    write_record(
        out,
        title="CUDA: views per second and the COIL-100-sized build against the CPU",
        command=command_line(__file__, argv),
        tables=[t],
        notes=note,
        raw={"quick": args.quick, **c},
    )
    return c


if __name__ == "__main__":
    main()
