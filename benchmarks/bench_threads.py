"""The commands' thread policy against one and two threads, quiet and beside a CPU-bound neighbour.

The same ``eigview coil`` run (the synthetic ``eigview demo`` where COIL-20 is absent) as
a subprocess with the default policy, one thread and two threads, on the machine as it
is ("quiet") and beside a CPU-bound neighbour the benchmark starts itself (one spinning
process per CPU, each ending by itself after a bounded time and killed after the
measurement). Beside them a reference job of plain matrix products on one and two
threads: its loaded/quiet ratio is what the scheduler leaves any CPU-bound job beside
this neighbour, the floor the command's ratio is read against. Every run is bounded by a
timeout. Run from the repository root:

``python benchmarks/bench_threads.py [--root DIR] [--quick] [--out FILE]``
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Any

if __name__ == "__main__" and not __package__:
    # Run as ``python benchmarks/bench_threads.py``: the benchmarks import as a package.
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks._coil import default_coil_root
from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from torch_eigview.scale import available_cpus

_SPIN = "import time\nend = time.monotonic() + {limit}\nwhile time.monotonic() < end:\n    pass\n"

# A fixed amount of CPU-bound work (matrix products) on N torch threads: the reference of
# what the CPU scheduler leaves any job beside the neighbour, whatever its thread policy.
_REFERENCE = (
    "import torch\ntorch.set_num_threads({threads})\n"
    "a = torch.randn(512, 512, generator=torch.Generator().manual_seed(0))\n"
    "for _ in range({iters}):\n    a = (a @ a).div_(a.norm())\n"
)


@contextmanager
def cpu_neighbour(n_procs: int, limit_s: float) -> Iterator[list[subprocess.Popen[bytes]]]:
    """``n_procs`` processes spinning on the CPU for at most ``limit_s`` seconds each.

    They end by themselves after ``limit_s`` (so a killed benchmark leaves nothing
    behind for long), and are killed on exit from the ``with`` block.
    """
    procs = [
        subprocess.Popen([sys.executable, "-c", _SPIN.format(limit=float(limit_s))]) for _ in range(n_procs)
    ]
    try:
        time.sleep(0.2)  # let them reach the spinning loop
        yield procs
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()


def run_python(argv: list[str], timeout_s: float, name: str) -> float | None:
    """Wall seconds of ``python ARGV`` (None when it ran past ``timeout_s``); ``name`` in its error.

    ``OMP_NUM_THREADS`` and ``MKL_NUM_THREADS`` are unset in the child, so that only its
    own settings (``--threads``, ``torch.set_num_threads``) decide.
    """
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    t0 = time.perf_counter()
    try:
        done = subprocess.run(
            [sys.executable, *argv],
            timeout=timeout_s,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
    except subprocess.TimeoutExpired:
        return None
    if done.returncode:
        raise RuntimeError(f"{name} failed ({done.returncode}): {done.stderr.strip()[-500:]}")
    return time.perf_counter() - t0


def run_command(args: list[str], timeout_s: float) -> float | None:
    """Wall seconds of ``python -m torch_eigview ARGS`` (None when it ran past ``timeout_s``)."""
    return run_python(["-m", "torch_eigview", *args], timeout_s, f"eigview {' '.join(args)}")


def quiet_and_loaded(
    setting: str, run: Callable[[], float | None], n_procs: int, timeout_s: float
) -> dict[str, Any]:
    """One row of the table: ``run`` on the machine as it is, then beside the neighbour."""
    quiet = run()
    with cpu_neighbour(n_procs, timeout_s + 5):
        loaded = run()
    ratio = None if quiet is None or loaded is None else loaded / quiet
    return {"setting": setting, "quiet_s": quiet, "loaded_s": loaded, "loaded_over_quiet": ratio}


def reference_rows(n_procs: int, timeout_s: float, iters: int) -> list[dict[str, Any]]:
    """The reference job on one and on two threads, quiet then beside the neighbour."""
    rows = []
    for n_threads in (1, 2):
        argv = ["-c", _REFERENCE.format(threads=n_threads, iters=iters)]
        name = f"reference: {n_threads} thread{'s' if n_threads > 1 else ''}"
        rows.append(quiet_and_loaded(name, partial(run_python, argv, timeout_s, name), n_procs, timeout_s))
    return rows


def _command(root: Path | None, objects: str) -> list[str]:
    """A COIL run when the images are there, else the synthetic demo (no figure)."""
    if root is not None and root.is_dir():
        return ["coil", "--folder", str(root), "--alpha", "10", "--objects", objects, "--quiet"]
    return ["demo", "--size", "48", "--png", "", "--quiet"]


def bench_threads(
    root: Path | None,
    objects: str = "1-4",
    timeout_s: float = 120.0,
    neighbour_procs: int | None = None,
    reference_iters: int = 400,
) -> dict[str, Any]:
    """The thread policy against one and two threads, quiet and beside a CPU-bound neighbour.

    Each setting runs the same command as a subprocess; quiet and loaded runs are
    interleaved per setting. The reference job, ``reference_iters`` products of 512 × 512
    matrices on one and on two torch threads, runs the same way (with the neighbour on
    every CPU its loaded/quiet ratio is about 1.5 for one busy thread and 2 for two).

    Returns:
        ``{"command", "rows": [{setting, quiet_s, loaded_s, loaded_over_quiet}],
        "references": [the same for the reference job], ...}``; a time is None where
        the run passed ``timeout_s``.
    """
    base = _command(root, objects)
    # The policy's workers (one thread per CPU, one object each) against one process thread
    # doing everything, with one and with two intra-op threads.
    one = ["--workers", "0"] if base[0] == "coil" else []
    settings = {
        "policy (default)": [],
        f"{' '.join(one)} --threads 1".strip(): [*one, "--threads", "1"],
        f"{' '.join(one)} --threads 2".strip(): [*one, "--threads", "2"],
    }
    n_procs = neighbour_procs or available_cpus()
    rows = [
        quiet_and_loaded(name, partial(run_command, [*base, *extra], timeout_s), n_procs, timeout_s)
        for name, extra in settings.items()
    ]
    return {
        "command": " ".join(base),
        # The command as the tables show it: the folder by its name, not this machine's path.
        "shown": " ".join(root.name if root is not None and a == str(root) else a for a in base),
        "neighbour_procs": n_procs,
        "timeout_s": timeout_s,
        "rows": rows,
        "references": reference_rows(n_procs, timeout_s, reference_iters),
    }


def threads_table(t: dict[str, Any]) -> dict[str, Any]:
    """Every setting's seconds, its loaded/quiet ratio and its time over the best setting's."""
    best = {
        key: min((r[key] for r in t["rows"] if r[key] is not None), default=None)
        for key in ("quiet_s", "loaded_s")
    }

    def over_best(r: dict[str, Any], key: str) -> float | None:
        return r[key] / best[key] if r[key] is not None and best[key] else None

    rows = [
        [
            r["setting"],
            r["quiet_s"],
            r["loaded_s"],
            r["loaded_over_quiet"],
            over_best(r, "quiet_s"),
            over_best(r, "loaded_s"),
        ]
        for r in t["rows"]
    ]
    rows += [
        [r["setting"], r["quiet_s"], r["loaded_s"], r["loaded_over_quiet"], None, None]
        for r in t.get("references", [])
    ]
    return table(
        f"`eigview {t.get('shown', t['command'])}`, quiet and beside {t['neighbour_procs']} spinning processes: seconds "
        f"(– past the {t['timeout_s']:.0f} s timeout), ratios to quiet and to the best setting",
        ["setting", "quiet s", "loaded s", "loaded / quiet", "quiet / best", "loaded / best"],
        rows,
    )


def verdicts(t: dict[str, Any]) -> list[str]:
    """Whether the policy stays within 1.3× of the best setting quiet and loaded, and within
    1.5× of its quiet time when loaded, and the scheduler's floor beside this neighbour."""
    lines = []
    policy = t["rows"][0]
    for key in ("quiet_s", "loaded_s"):
        times = [r[key] for r in t["rows"] if r[key] is not None]
        if policy[key] is not None and times:
            share = policy[key] / min(times)
            lines.append(
                f"policy / best ({key[:-2]}): {share:.2f} (target <= 1.3: {'met' if share <= 1.3 else 'NOT met'})"
            )
    ratio = policy["loaded_over_quiet"]
    if ratio is not None:
        lines.append(
            f"policy loaded / quiet: {ratio:.2f} (target <= 1.5: {'met' if ratio <= 1.5 else 'NOT met'})"
        )
    floor = {r["setting"]: r["loaded_over_quiet"] for r in t.get("references", [])}
    if floor and all(v is not None for v in floor.values()):
        lines.append(
            "the scheduler's floor beside this neighbour, the reference job's loaded / quiet: "
            + ", ".join(f"{v:.2f} ({k.removeprefix('reference: ')})" for k, v in floor.items())
        )
    return lines


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "objects 1-2, 100 reference products, a 60 s timeout")
    p.add_argument(
        "--root",
        default=None,
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else "
        "../shared/data/coil-20-proc; the synthetic demo where that is absent)",
    )
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    if args.root is not None and not Path(args.root).is_dir():
        p.error(f"--root={args.root!r} is not an existing folder of COIL-20 images")
    root = Path(args.root) if args.root is not None else default_coil_root()
    if args.quick:
        t = bench_threads(root, "1-2", 60.0, reference_iters=100)
    else:
        t = bench_threads(root, "1-4", 180.0, reference_iters=400)
    tab = threads_table(t)
    lines = verdicts(t)
    print(format_table(tab), *lines, sep="\n")
    write_record(
        out,
        title="Thread policy: quiet and beside a CPU-bound neighbour",
        command=command_line(__file__, argv),
        tables=[tab],
        notes="\n".join(f"- {line}" for line in lines),
        raw={"quick": args.quick, **t},
    )
    return t


if __name__ == "__main__":
    main()
