"""A fit's peak memory and time on a turntable of many objects: merged against held at once,
and the eigen step against scikit-learn's IncrementalPCA.

The data set is the kind users bring, rendered (``benchmarks/_turntable.py``): 80 objects,
16 views 22.5° apart, RGB on a coloured, textured backdrop with a mask per view, in a
manifest. Two parts, each run in fresh processes:

1. ``eigview fit --manifest ... --circle 8`` (the gallery: every degree round the
   turntable, 360 views per object; the background rule follows the masks): peak resident
   set (``/usr/bin/time -v``) and wall time for 20 and 80 objects at each size, the
   default (a gallery of more than ``--max-views`` views merged as it is synthesized)
   against ``--max-views`` beyond the gallery (held and fitted at once, the exact
   eigenspace; where it fits in memory), in turns; their eigenvalues and accuracy on
   the 8 views per object that are no seeds.
2. The eigen step alone on the same synthesized views, one object's 360 unit-norm views
   at a time: ours (``IncrementalEigenspace``, merged) against
   ``sklearn.decomposition.IncrementalPCA(15)`` (``partial_fit`` per object), each in its
   own process: the extra peak memory during the step, its seconds, and the largest
   relative error of the 15 leading eigenvalues against the exact eigenspace (float64,
   held at once).

Run from the repository root (the data sets are rendered first into ``--data``, once):

``python benchmarks/bench_fit_memory.py [--data DIR] [--sizes 64 128] [--rounds 2] [--quick] [--out FILE]``
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_fit_memory.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from benchmarks._turntable import write_turntable

K = 15


def subset(manifest: Path, n_objects: int) -> Path:
    """A manifest of the first ``n_objects`` objects of ``manifest``, beside it."""
    rows = manifest.read_text(encoding="utf-8").splitlines()
    kept, objects = [rows[0]], []
    for row in rows[1:]:
        name = row.split(",")[1]
        if name not in objects:
            objects.append(name)
        if objects.index(name) < n_objects:
            kept.append(row)
    out = manifest.with_name(f"views{n_objects}.csv")
    out.write_text("\n".join(kept) + "\n", encoding="utf-8")
    return out


def _time_v(argv: list[str], cwd: Path) -> dict[str, Any]:
    """``argv`` under ``/usr/bin/time -v``: its exit status, peak resident set and wall time."""
    t0 = time.perf_counter()
    proc = subprocess.run(["/usr/bin/time", "-v", *argv], cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    peak = next(
        (int(line.split()[-1]) * 1024 for line in proc.stderr.splitlines() if "Maximum resident set" in line),
        0,
    )
    return {"status": proc.returncode, "peak_bytes": peak, "seconds": wall, "stderr": proc.stderr[-2000:]}


def fit_run(manifest: Path, model: Path, max_views: int | None) -> dict[str, Any]:
    argv = [sys.executable, "-m", "torch_eigview", "fit", "--manifest", str(manifest), "--circle", "8"]
    argv += ["--quiet", "--out", str(model)] + ([] if max_views is None else ["--max-views", str(max_views)])
    return _time_v(argv, manifest.parent)


def model_figures(model: Path, manifest: Path) -> dict[str, Any]:
    """The model's eigenvalues and its accuracy on the manifest's views that are no seeds."""
    import torch

    from torch_eigview.io import load_model

    values = load_model(model).recognizer.projection.eigenvalues.double().tolist()
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "r.json"
        argv = [sys.executable, "-m", "torch_eigview", "evaluate", "--model", str(model)]
        argv += ["--manifest", str(manifest), "--exclude-seeds", "--quiet", "--json", str(report)]
        subprocess.run(argv, cwd=manifest.parent, capture_output=True, check=True)
        accuracy = json.loads(report.read_text())["accuracy"]
    del torch
    return {"eigenvalues": values, "accuracy": accuracy}


# ------------------------------------------------------------------ part 2: the eigen step
STEP = r"""
import json, sys, time
import torch
from benchmarks._fit_case import PeakRss
from benchmarks.bench_fit_memory import galleries
method, manifest, size = sys.argv[1], sys.argv[2], int(sys.argv[3])
blocks = galleries(manifest, size)
seconds, values = 0.0, None
with PeakRss() as rss:
    if method == "ours":
        from torch_eigview.decomposition import IncrementalEigenspace
        model = IncrementalEigenspace(15)
        for x in blocks:
            t0 = time.perf_counter(); model.partial_fit(x); seconds += time.perf_counter() - t0
        values = model.eigenvalues_.double().tolist()
    elif method == "ipca":
        from sklearn.decomposition import IncrementalPCA
        model = IncrementalPCA(15)
        n = 0
        for x in blocks:
            arr = x.numpy(); n += arr.shape[0]
            t0 = time.perf_counter(); model.partial_fit(arr); seconds += time.perf_counter() - t0
        values = (model.explained_variance_ * (n - 1)).tolist()
    else:  # exact: every view held, float64
        from torch_eigview.decomposition import Eigenspace
        x = torch.cat(list(blocks)).double()
        t0 = time.perf_counter(); values = Eigenspace(15).fit(x).eigenvalues_.tolist(); seconds = time.perf_counter() - t0
print(json.dumps({"peak_bytes": rss.peak - rss.baseline, "seconds": seconds, "eigenvalues": values}))
"""


def galleries(manifest: str, size: int) -> Any:
    """Per object its 360 unit-norm synthesized views (360, N) float32, as ``eigview fit
    --circle 8 --size S S`` makes them (the masks given, the backdrop set to 0)."""
    import torch

    from torch_eigview.datasets import BackgroundModel, ViewManifest, read_view
    from torch_eigview.nn import unit_rows
    from torch_eigview.scale import threads
    from torch_eigview.synthesis import SynthesisOptions, synthesize_circle

    views = ViewManifest.from_csv(manifest)
    azimuths = [45.0 * k for k in range(8)]
    with threads(1):
        for obj in views.objects:
            entries = [next(e for e in views.views(obj) if abs(e.azimuth - a) < 1e-6) for a in azimuths]
            read = [
                read_view(e.path, e.mask, size=(size, size), background=BackgroundModel()) for e in entries
            ]
            seeds = torch.stack([image for image, _ in read])
            masks = torch.stack([mask[0] for _, mask in read])
            out = synthesize_circle(seeds, 1.0, SynthesisOptions(), masks)
            yield unit_rows(out.views)


def step_run(method: str, manifest: Path, size: int) -> dict[str, Any]:
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run(
        [sys.executable, "-c", STEP, method, str(manifest), str(size)],
        cwd=root,
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        return {"error": proc.stderr[-1500:]}
    result: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def _rel(values: list[float], exact: list[float]) -> float:
    return max(abs(a - b) / b for a, b in zip(values[:K], exact[:K], strict=True))


def main(argv: list[str] | None = None) -> dict[str, Any]:
    p = parser(__file__, __doc__ or "", "10 objects at 32 × 32, one round")
    p.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "torch_eigview_turntable")
    p.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    p.add_argument("--rounds", type=int, default=2, help="A/B pairs of the fits, in turns")
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    sizes, counts, rounds = ([32], (5, 10), 1) if args.quick else (args.sizes, (20, 80), args.rounds)
    raw: dict[str, Any] = {"fits": {}, "steps": {}}
    rows, step_rows = [], []
    for size in sizes:
        folder = args.data / f"ring{size}"
        manifest = folder / "views.csv"
        if not manifest.exists():
            print(f"rendering {max(counts)} objects at {size} x {size} into {folder} ...", flush=True)
            write_turntable(folder, max(counts), size)
        for n in counts:
            listed = subset(manifest, n)
            held_at_once = None if size >= 128 and n > 20 else 10**7  # where the exact fit fits in 24 GiB
            runs: dict[str, list[dict[str, Any]]] = {"merged": [], "held at once": []}
            for _ in range(rounds):
                runs["merged"].append(fit_run(listed, folder / f"merged{n}.pt", None))
                if held_at_once is not None:
                    runs["held at once"].append(fit_run(listed, folder / f"held{n}.pt", held_at_once))
            key = f"{size}/{n}"
            raw["fits"][key] = runs
            merged = model_figures(folder / f"merged{n}.pt", listed)
            held = model_figures(folder / f"held{n}.pt", listed) if runs["held at once"] else None
            ratio = None
            if held is not None:
                ratio = sum(r["seconds"] for r in runs["merged"]) / sum(
                    r["seconds"] for r in runs["held at once"]
                )
            rows.append(
                [
                    f"{size} × {size}",
                    n,
                    max(r["peak_bytes"] for r in runs["merged"]) / 2**30,
                    min(r["seconds"] for r in runs["merged"]),
                    None if held is None else max(r["peak_bytes"] for r in runs["held at once"]) / 2**30,
                    None if held is None else min(r["seconds"] for r in runs["held at once"]),
                    ratio,
                    merged["accuracy"],
                    None if held is None else held["accuracy"],
                    None if held is None else _rel(merged["eigenvalues"], held["eigenvalues"]),
                ]
            )
            raw["fits"][key + " figures"] = {"merged": merged, "held at once": held}
            print(
                format_table(
                    table(
                        "fit",
                        [
                            "size",
                            "objects",
                            "merged GiB",
                            "merged s",
                            "held GiB",
                            "held s",
                            "time ratio",
                            "acc merged",
                            "acc held",
                            "eig rel",
                        ],
                        rows[-1:],
                    )
                ),
                flush=True,
            )
        if size <= 64 or args.quick:
            listed = subset(manifest, max(counts))
            steps = {m: step_run(m, listed, size) for m in ("exact", "ours", "ipca")}
            raw["steps"][str(size)] = steps
            exact = steps["exact"].get("eigenvalues")
            for name in ("ours", "ipca"):
                s = steps[name]
                if "error" in s:
                    step_rows.append([f"{size} × {size}", name, None, None, None])
                    continue
                step_rows.append(
                    [
                        f"{size} × {size}",
                        "IncrementalEigenspace (ours)" if name == "ours" else "sklearn IncrementalPCA(15)",
                        s["peak_bytes"] / 2**20,
                        s["seconds"],
                        None if exact is None else _rel(s["eigenvalues"], exact),
                    ]
                )
            print(
                format_table(
                    table("eigen step", ["size", "method", "extra peak MiB", "seconds", "eig rel"], step_rows)
                ),
                flush=True,
            )
    tables = [
        table(
            f"eigview fit --circle 8 on the rendered turntable ({max(counts)} objects, 16 views 22.5° apart, RGB "
            "with masks; 360 gallery views per object): peak resident set (GiB) and wall seconds, the default "
            "(merged) against the gallery held at once (--max-views beyond it); the time ratio merged / held over "
            "the rounds in turns; accuracy (%) on the 8 views per object that are no seeds; the largest relative "
            f"error of the {K} eigenvalues, merged against held.",
            [
                "size",
                "objects",
                "merged GiB",
                "merged s",
                "held GiB",
                "held s",
                "time ratio",
                "acc merged",
                "acc held",
                "eig rel",
            ],
            rows,
        ),
        table(
            f"The eigen step alone on the same unit-norm views, one object (360 views) a block: the extra peak "
            f"memory of the step (MiB), its seconds, and the largest relative error of the {K} leading "
            "eigenvalues against the exact eigenspace (float64, held at once).",
            ["size", "method", "extra peak MiB", "seconds", "eig rel"],
            step_rows,
        ),
    ]
    write_record(
        out,
        title="A fit's memory on a turntable of many objects",
        command=command_line(__file__, argv if argv is not None else sys.argv[1:]),
        tables=tables,
        raw=raw,
    )
    return raw


if __name__ == "__main__":
    main()
