"""The distributed eigenspace build: objects sharded over ``torch.distributed`` ranks.

Each rank synthesizes the views of its own objects (COIL-20's ``nvs`` gallery: two seed
views α apart, views over ``--synth``; random smooth views without ``--root``) and
:func:`~torch_eigview.scale.fit_distributed` reduces the eigenspace with collectives, the
same as one process's. Rank 0 reports the seconds of the views and of the eigen step, and
their ratio. Run under torchrun from the repository root (gloo on CPU, nccl where CUDA is
available)::

    torchrun --nproc_per_node 2 --master_addr 127.0.0.1 benchmarks/bench_distributed.py --root ../shared/data/coil-20-proc --alpha 5

A collective that does not complete within ``--timeout`` raises a ``TimeoutError``
naming the rank instead of hanging. ``--save FILE`` writes the projection's ``state_dict``
(checksummed; read it with ``torch_eigview.io.checkpoint.load_state_dict``).
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``benchmarks/bench_distributed.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

import torch
import torch.distributed as dist

from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from benchmarks._views import smooth_views
from torch_eigview import CoilFolder, synthesize_views
from torch_eigview.evaluation.coil import angle_range
from torch_eigview.files import check_outputs
from torch_eigview.io.checkpoint import save_state_dict
from torch_eigview.nn import unit_rows
from torch_eigview.scale import fit_distributed

METHODS = ("exact", "randomized")


def _parser() -> argparse.ArgumentParser:
    p = parser(__file__, __doc__, "4 synthetic objects of 32×32 without --root, objects 1-4 with it")
    p.prog = "torchrun --nproc_per_node R benchmarks/bench_distributed.py"
    p.add_argument("--root", default=None, help="COIL folder; omit for synthetic smooth views")
    p.add_argument("--alpha", type=float, default=5.0, help="angle between the two seed views (degrees)")
    p.add_argument(
        "--synth", type=float, nargs=3, default=(-20.0, 20.0, 1.0), metavar=("START", "STOP", "STEP")
    )
    p.add_argument("--objects", type=int, default=20, help="objects (the folder's first N with --root)")
    p.add_argument("--size", type=int, default=128, help="synthetic image size (without --root)")
    p.add_argument("--components", type=int, default=15)
    p.add_argument("--method", choices=METHODS, default="exact")
    p.add_argument("--timeout", type=float, default=30.0, help="collective timeout in seconds")
    p.add_argument(
        "--save",
        default=None,
        help="rank 0 writes the EigenProjection state_dict here, checksummed (read it with "
        "torch_eigview.io.checkpoint.load_state_dict)",
    )
    return p


def local_views(args: argparse.Namespace, rank: int, world: int) -> torch.Tensor:
    """(P_rank, N) unit-norm views of this rank's objects (every ``world``-th from ``rank``)."""
    if args.root is None:
        objects = list(range(args.objects))[rank::world]
        blocks = [smooth_views(o, 41, 1, args.size) for o in objects]
    else:
        folder = CoilFolder(args.root)
        thetas = angle_range(args.synth[0], args.synth[1], args.synth[2], "synth")
        blocks = []
        for obj in folder.objects[: args.objects][rank::world]:
            seeds = folder.images(obj, [0.0, args.alpha])
            blocks.append(synthesize_views(seeds, args.alpha, thetas).views)
    if not blocks:
        return torch.empty(0, 1)
    return unit_rows(torch.cat(blocks))  # unit L2 norm per view, as the COIL experiment does


def main(argv: Sequence[str] | None = None) -> dict[str, Any] | None:
    """Entry point under torchrun (reads RANK, WORLD_SIZE, MASTER_ADDR/PORT from the
    environment); rank 0 returns its summary, the other ranks None."""
    argv = list(sys.argv[1:] if argv is None else argv)
    p = _parser()
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    if args.quick:
        args.objects, args.size = 4, 32
    # Every rank, before the group forms: all stop together, none waits on the others.
    check_out(p, out)
    try:
        check_outputs([("--out", out), ("--save", args.save)], inputs=[("--root", args.root)])
    except ValueError as exc:
        p.error(str(exc))
    backend = "nccl" if torch.cuda.is_available() else "gloo"
    dist.init_process_group(backend, timeout=datetime.timedelta(seconds=args.timeout))
    try:
        rank, world = dist.get_rank(), dist.get_world_size()
        if backend == "nccl":
            torch.cuda.set_device(rank % torch.cuda.device_count())
        t0 = time.perf_counter()
        views = local_views(args, rank, world)
        t1 = time.perf_counter()
        if backend == "nccl":
            views = views.cuda()
        space = fit_distributed(views, args.components, solver=args.method)
        t2 = time.perf_counter()
        if rank != 0:
            return None
        summary = {
            "world_size": world,
            "backend": backend,
            "method": args.method,
            "n_views": space.n_samples_,
            "n_features": space.n_features_in_,
            "n_components": space.n_components_,
            "eigenvalues": [float(v) for v in space.eigenvalues_[:5]],
            "seconds": {"views": t1 - t0, "eigen": t2 - t1},
        }
        what = f"COIL-20 at α = {args.alpha:g}" if args.root else "random smooth views"
        t = table(
            f"{summary['n_views']} × {summary['n_features']} views ({what}) over {world} rank(s), {backend}, "
            f"{args.method} fit, k = {args.components}: seconds of rank 0",
            ["ranks", "views s", "eigen s", "eigen / views"],
            [[world, t1 - t0, t2 - t1, (t2 - t1) / (t1 - t0) if t1 > t0 else None]],
        )
        print(format_table(t))
        # torchrun sets OMP_NUM_THREADS=1 in every rank itself: not part of the command.
        launcher = ("torchrun", "--nproc_per_node", str(world), "--master_addr", "127.0.0.1")
        write_record(
            out,
            title="Distributed build: objects sharded over torch.distributed ranks",
            command=command_line(__file__, argv, launcher=launcher, thread_vars=False),
            tables=[t],
            raw={"quick": args.quick, **summary},
        )
        if args.save:
            save_state_dict(space.to_module().cpu().state_dict(), args.save)
        return summary
    finally:
        dist.destroy_process_group()


if __name__ == "__main__":
    main()
