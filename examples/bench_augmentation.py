"""Benchmark: the random turntable rotation on a batch of different objects, one call vs a loop.

A batch of B different rendered objects (the synthetic renderer's shapes, each with its
own texture seed), each a pair of seed views at 0 and α with its exact correspondence,
is turned by B different angles drawn by :class:`RandomTurntableRotation` (p = 1):

- *batched*: one call of the augmentation, all B objects at their own θ in one warp;
- *loop*: a Python loop over the samples, one :class:`NovelViewWarp` call per object at
  its θ (what a batch of different objects needed before per-object angles).

Both run in the same process, interleaved repeat by repeat, so that a load change on the
machine hits both; the medians and their ratio are printed. This prints figures, it is
not a timed test. Run with one thread for a figure that does not depend on the cores:

``OMP_NUM_THREADS=1 python examples/bench_augmentation.py [--batch 64] [--size 64] [--repeats 11]``
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import torch

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


def interleaved_medians(fns: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median seconds of each function, the functions alternating within every repeat."""
    for fn in fns.values():
        fn()  # warm-up: first-call allocations, kernel selection
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return {name: statistics.median(ts) for name, ts in times.items()}


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=64, help="number of different objects B")
    parser.add_argument("--size", type=int, default=64, help="image side in pixels")
    parser.add_argument("--alpha", type=float, default=10.0, help="angle of the second seed view")
    parser.add_argument("--degrees", type=float, default=20.0, help="θ drawn from (-degrees, degrees)")
    parser.add_argument("--repeats", type=int, default=11)
    parser.add_argument("--quick", action="store_true", help="4 objects of 32×32, 2 repeats (for tests)")
    args = parser.parse_args(argv)
    if args.quick:
        args.batch, args.size, args.repeats = 4, 32, 2

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
    print(f"max |batched - loop| = {diff:.2e}")
    print(
        f"median of {args.repeats}: one call {medians['batched'] * 1e3:.1f} ms, "
        f"loop over {args.batch} samples {medians['loop'] * 1e3:.1f} ms, ratio {ratio:.2f}×"
    )
    return {"batched_s": medians["batched"], "loop_s": medians["loop"], "ratio": ratio, "max_diff": diff}


if __name__ == "__main__":
    main()
