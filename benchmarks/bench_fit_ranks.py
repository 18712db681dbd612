"""``eigview fit`` on one process against ``torchrun --nproc-per-node R``: time, memory, agreement.

The rendered turntable of ``bench_fit_memory.py`` (``--objects`` objects, 16 views 22.5°
apart, RGB with masks), fitted round the full circle (``--circle 8``) by one process and by
R processes under torchrun, in turns (``--rounds`` pairs): the wall seconds and the peak
resident set of the largest process of each, their ratio, and how far the two models lie
apart: the largest relative difference of the eigenvalues and of the gallery codes, the
share of the views that are no seeds given the same label, and each model's accuracy on
them. Below the rank cap (``max_rank``) the two agree to rounding; past it each drops its
smallest eigenpairs at other merges, within the reported truncation bound.

Run from the repository root::

    python benchmarks/bench_fit_ranks.py --size 64 --objects 20 --ranks 2
"""

from __future__ import annotations

import socket
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``benchmarks/bench_fit_ranks.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from benchmarks._turntable import write_turntable
from benchmarks.bench_fit_memory import _time_v, model_figures, subset


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def fit_argv(manifest: Path, model: Path, ranks: int) -> list[str]:
    """``eigview fit --circle 8`` on ``manifest``, under torchrun when ``ranks`` > 1."""
    launch = [sys.executable]
    if ranks > 1:
        launch += [
            "-m",
            "torch.distributed.run",
            "--nproc-per-node",
            str(ranks),
            "--master-port",
            str(_port()),
        ]
    return [
        *launch,
        "-m",
        "torch_eigview",
        "fit",
        "--manifest",
        str(manifest),
        "--circle",
        "8",
        "--quiet",
        "--out",
        str(model),
    ]


def agreement(one: Path, many: Path, manifest: Path) -> dict[str, float]:
    """How far the two models lie apart (see the module's docstring)."""
    import torch

    from torch_eigview.io import load_model

    a, b = load_model(one), load_model(many)
    va, vb = a.recognizer.projection.eigenvalues.double(), b.recognizer.projection.eigenvalues.double()
    ca, cb = a.recognizer.codes.double(), b.recognizer.codes.double()
    views = [line.split(",")[0] for line in manifest.read_text().splitlines()[1:]]
    views = [manifest.parent / v for v in views]
    same = (a.predict_files(views).labels == b.predict_files(views).labels).double().mean()
    del torch
    return {
        "eig_rel": float(((va - vb).abs() / va.abs()).max()),
        "codes_rel": float((ca - cb).abs().max() / ca.abs().max()),
        "same_label": 100.0 * float(same),
    }


def main(argv: list[str] | None = None) -> dict[str, Any]:
    p = parser(__file__, __doc__ or "", "4 objects at 32 × 32, 2 ranks, one round")
    p.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "torch_eigview_turntable")
    p.add_argument("--size", type=int, default=64, help="image side of the rendered turntable")
    p.add_argument("--objects", type=int, default=20)
    p.add_argument("--ranks", type=int, default=2, help="processes under torchrun, >= 2")
    p.add_argument("--rounds", type=int, default=3, help="pairs of fits, in turns")
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    if args.ranks < 2 or args.objects < args.ranks or args.rounds < 1 or args.size < 16:
        p.error("--ranks must be >= 2, --objects at least --ranks, --rounds >= 1 and --size >= 16")
    size, objects, rounds = (32, 4, 1) if args.quick else (args.size, args.objects, args.rounds)
    folder = args.data / f"ring{size}"
    manifest = folder / "views.csv"
    have = (
        {row.split(",")[1] for row in manifest.read_text().splitlines()[1:]} if manifest.exists() else set()
    )
    if len(have) < objects:
        print(f"rendering {objects} objects at {size} x {size} into {folder} ...", flush=True)
        write_turntable(folder, objects, size)
    listed = subset(manifest, objects)
    runs: dict[str, list[dict[str, Any]]] = {"one": [], "ranks": []}
    for _ in range(rounds):
        runs["one"].append(_time_v(fit_argv(listed, folder / "one.pt", 1), folder))
        runs["ranks"].append(_time_v(fit_argv(listed, folder / "ranks.pt", args.ranks), folder))
    failed = [r["stderr"] for rs in runs.values() for r in rs if r["status"] != 0]
    if failed:
        raise SystemExit(f"a fit failed:\n{failed[0]}")
    ratio = statistics.median(
        b["seconds"] / a["seconds"] for a, b in zip(runs["one"], runs["ranks"], strict=True)
    )
    agree = agreement(folder / "one.pt", folder / "ranks.pt", listed)
    acc_one = model_figures(folder / "one.pt", listed)["accuracy"]
    acc_ranks = model_figures(folder / "ranks.pt", listed)["accuracy"]
    median = lambda key, name: statistics.median(r[key] for r in runs[name])  # noqa: E731
    rows = [
        [
            f"{size} × {size}",
            objects,
            args.ranks if not args.quick else 2,
            median("seconds", "one"),
            median("seconds", "ranks"),
            ratio,
            median("peak_bytes", "one") / 2**30,
            median("peak_bytes", "ranks") / 2**30,
            agree["eig_rel"],
            agree["codes_rel"],
            agree["same_label"],
            acc_one,
            acc_ranks,
        ]
    ]
    result = table(
        "eigview fit --circle 8 on the rendered turntable: one process against R ranks under torchrun, "
        "in turns (medians): wall seconds, their ratio ranks / one, the peak resident set of the largest "
        "process (GiB), the largest relative difference of the 15 eigenvalues and of the gallery codes, "
        "the share (%) of all views given the same label, and each model's accuracy (%) on the views "
        "that are no seeds.",
        ["size", "objects", "ranks", "one s", "ranks s", "ratio", "one GiB", "rank GiB", "eig rel", "codes rel",
         "same label", "acc one", "acc ranks"],
        rows,
    )  # fmt: skip
    print(format_table(result))
    write_record(
        out,
        title="eigview fit over the ranks of torchrun",
        command=command_line(__file__, argv if argv is not None else sys.argv[1:]),
        tables=[result],
        raw={"runs": runs, "agreement": agree},
    )
    return {"rows": rows, "agreement": agree}


if __name__ == "__main__":
    main()
