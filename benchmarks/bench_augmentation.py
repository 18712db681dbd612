"""The random turntable rotation of a batch of different objects: one call against a loop over the samples.

A batch of B different rendered objects (the synthetic renderer's shapes, each with its
own texture seed), each a pair of seed views at 0 and α with its exact correspondence,
is turned by B different angles drawn by
:class:`~torch_eigview.warp.RandomTurntableRotation` (p = 1):

- *one call*: the augmentation once, all B objects at their own θ in one warp;
- *loop*: a Python loop over the samples, one :class:`~torch_eigview.NovelViewWarp` call
  per object at its θ (the reference of the ratio).

Both run in the same process, interleaved repeat by repeat, so that a load change on the
machine hits both; the medians and their ratio are reported. Run with one thread for a
figure that does not depend on the cores, from the repository root:

``OMP_NUM_THREADS=1 python benchmarks/bench_augmentation.py [--batch 64] [--size 64] [--repeats 11] [--quick] [--out FILE]``
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_augmentation.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import torch

from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from benchmarks._timing import interleaved_medians
from torch_eigview.datasets import SHAPES, OrthographicCamera, exact_correspondence, make_object, render
from torch_eigview.geometry import Correspondence
from torch_eigview.warp import NovelViewWarp, RandomTurntableRotation


def make_batch(batch: int, size: int, alpha: float) -> tuple[torch.Tensor, torch.Tensor, Correspondence]:
    """B different objects: (B, 1, H, W) seed views at 0 and ``alpha``, their (B, H, W) correspondence."""
    camera = OrthographicCamera(size)
    view1, view2, corrs = [], [], []
    for i in range(batch):
        obj = make_object(SHAPES[i % len(SHAPES)], seed=i // len(SHAPES))
        view1.append(render(obj, 0.0, camera).image)
        view2.append(render(obj, alpha, camera).image)
        corrs.append(exact_correspondence(obj, alpha, camera))
    return torch.stack(view1), torch.stack(view2), Correspondence.collate(corrs)


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "4 objects of 32×32, 2 repeats")
    p.add_argument("--batch", type=int, default=64, help="number of different objects B")
    p.add_argument("--size", type=int, default=64, help="image side in pixels")
    p.add_argument("--alpha", type=float, default=10.0, help="angle of the second seed view")
    p.add_argument("--degrees", type=float, default=20.0, help="θ drawn from (-degrees, degrees)")
    p.add_argument("--repeats", type=int, default=11)
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    if args.quick:
        args.batch, args.size, args.repeats = 4, 32, 2
    if min(args.batch, args.size, args.repeats) < 1:
        p.error(f"--batch, --size and --repeats must be >= 1, got {args.batch}, {args.size}, {args.repeats}")

    t0 = time.perf_counter()
    view1, view2, corr = make_batch(args.batch, args.size, args.alpha)
    print(
        f"{args.batch} objects of {args.size}×{args.size} rendered in {time.perf_counter() - t0:.1f} s "
        f"(threads: {torch.get_num_threads()})"
    )
    torch.manual_seed(0)
    augment = RandomTurntableRotation(args.degrees, args.alpha, p=1.0)
    params = augment.forward_parameters(view1.shape)
    thetas = params["degrees"]
    warp: NovelViewWarp = augment.warp

    def batched() -> torch.Tensor:
        return augment(view1, view2, correspondence=corr, params=params)

    def loop() -> torch.Tensor:
        return torch.cat(
            [
                warp(view1[i : i + 1], view2[i : i + 1], correspondence=corr[i], thetas=[t])[:, 0]
                for i, t in enumerate(thetas.tolist())
            ]
        )

    with torch.no_grad():
        diff = float((batched() - loop()).abs().max())
        medians = interleaved_medians({"batched": batched, "loop": loop}, args.repeats)
    ratio = medians["loop"] / medians["batched"]
    result = {
        "batch": args.batch,
        "size": args.size,
        "repeats": args.repeats,
        "threads": torch.get_num_threads(),
        "batched_s": medians["batched"],
        "loop_s": medians["loop"],
        "ratio": ratio,
        "max_diff": diff,
    }
    t = table(
        f"{args.batch} objects of {args.size}×{args.size} turned by their own angles, median of "
        f"{args.repeats} interleaved repeats on {result['threads']} thread(s)",
        ["objects", "one call ms", "loop ms", "loop / one call", "largest difference"],
        [[args.batch, medians["batched"] * 1e3, medians["loop"] * 1e3, ratio, diff]],
    )
    print(format_table(t))
    write_record(
        out,
        title="Random turntable rotation: one call against a loop over the samples",
        command=command_line(__file__, argv),
        tables=[t],
        raw={"quick": args.quick, **result},
    )
    return result


if __name__ == "__main__":
    main()
