"""The distributed COIL build: objects sharded over ``torch.distributed`` ranks.

Run it under torchrun (gloo on CPU, nccl where CUDA is available)::

    torchrun --nproc_per_node 2 -m torch_eigview.apps.distributed --root ../shared/data/coil-20-proc --alpha 5
"""

from __future__ import annotations

import argparse
import datetime
import json
import time
from collections.abc import Sequence

import torch
import torch.distributed as dist

from torch_eigview.files import check_outputs, write_json
from torch_eigview.io.checkpoint import save_state_dict
from torch_eigview.nn.functional import unit_rows
from torch_eigview.scale.distributed import fit_distributed

__all__ = ["main"]

_METHODS = ("exact", "randomized")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="torchrun --nproc_per_node R -m torch_eigview.apps.distributed",
        description="COIL eigenspace with objects sharded over torch.distributed ranks.",
    )
    p.add_argument("--root", default=None, help="COIL folder; omit for synthetic smooth views")
    p.add_argument("--alpha", type=float, default=5.0, help="angle between the two seed views (degrees)")
    p.add_argument(
        "--synth", type=float, nargs=3, default=(-20.0, 20.0, 1.0), metavar=("START", "STOP", "STEP")
    )
    p.add_argument("--objects", type=int, default=20, help="synthetic objects (without --root)")
    p.add_argument("--size", type=int, default=128, help="synthetic image size (without --root)")
    p.add_argument("--components", type=int, default=15)
    p.add_argument("--method", choices=_METHODS, default="exact")
    p.add_argument("--timeout", type=float, default=30.0, help="collective timeout in seconds")
    p.add_argument(
        "--save",
        default=None,
        help="rank 0 writes the EigenProjection state_dict here, checksummed (read it with "
        "torch_eigview.io.checkpoint.load_state_dict)",
    )
    p.add_argument("--json", default=None, help="rank 0 writes a summary here")
    return p


def _local_views(args: argparse.Namespace, rank: int, world: int) -> torch.Tensor:
    if args.root is None:
        from torch_eigview.apps.bench_scaling import smooth_views

        objects = list(range(args.objects))[rank::world]
        blocks = [smooth_views(o, 41, 1, args.size) for o in objects]
    else:
        from torch_eigview.datasets.coil import CoilFolder
        from torch_eigview.evaluation.coil import angle_range
        from torch_eigview.synthesis import synthesize_views

        folder = CoilFolder(args.root)
        thetas = angle_range(args.synth[0], args.synth[1], args.synth[2], "synth")
        blocks = []
        for obj in folder.objects[rank::world]:
            seeds = folder.images(obj, [0.0, args.alpha])
            blocks.append(synthesize_views(seeds, args.alpha, thetas).views)
    if not blocks:
        return torch.empty(0, 1)
    x = torch.cat(blocks)
    return unit_rows(x).reshape(x.shape)  # unit L2 norm per view, as the COIL experiment does


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point under torchrun (reads RANK, WORLD_SIZE, MASTER_ADDR/PORT from the env)."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:  # every rank, before the group forms: all stop together, none waits on the others
        check_outputs([("--json", args.json), ("--save", args.save)], inputs=[("--root", args.root)])
    except ValueError as exc:
        parser.exit(2, f"torch_eigview.apps.distributed: error: {exc}\n")
    backend = "nccl" if torch.cuda.is_available() else "gloo"
    dist.init_process_group(backend, timeout=datetime.timedelta(seconds=args.timeout))
    try:
        rank, world = dist.get_rank(), dist.get_world_size()
        if backend == "nccl":
            torch.cuda.set_device(rank % torch.cuda.device_count())
        t0 = time.perf_counter()
        views = _local_views(args, rank, world)
        t1 = time.perf_counter()
        if backend == "nccl":
            views = views.cuda()
        space = fit_distributed(views, args.components, method=args.method)
        t2 = time.perf_counter()
        if rank == 0:
            summary = {
                "world_size": world,
                "backend": backend,
                "method": args.method,
                "n_views": space.n_samples_,
                "n_features": space.n_features_in_,
                "n_components": space.n_components_,
                "eigenvalues": [float(v) for v in space.eigenvalues_[:5]],
                "seconds": {"views": round(t1 - t0, 3), "eigen": round(t2 - t1, 3)},
            }
            print(json.dumps(summary))
            if args.json:
                write_json(args.json, summary)
            if args.save:
                save_state_dict(args.save, space.to_module().cpu().state_dict())
    finally:
        dist.destroy_process_group()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
