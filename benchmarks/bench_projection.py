"""Projection throughput (images/s): torch eager, torch.compile, onnxruntime and scikit-learn's PCA.

For 128×128 images, k = 15 and 64, batches 1, 32 and 256, the same basis in

- ``eager``: :class:`~torch_eigview.EigenProjection` under ``torch.inference_mode``;
- ``compile``: the same module through ``torch.compile`` (inductor by default);
- ``ort-plain``: onnxruntime on the projection's ``forward`` as written (Sub, MatMul),
  default session options (but no spinning, as for every session here);
- ``ort``: onnxruntime on the folded graph ``z = x @ Wᵀ − mean @ Wᵀ``
  (:func:`torch_eigview.io.export_projection`), ``intra_op_num_threads`` = the torch
  threads, all graph optimizations;
- ``sklearn``: ``PCA.transform`` with ``components_`` and ``mean_`` set to the same basis
  (the reference of the ratios).

Each entry is the median of repeated calls after warm-up runs. Three libraries share the
cores here (torch's OpenMP pool, numpy's BLAS pool, onnxruntime's pool); a pool that
spin-waits after its call starves the next one, so OpenMP waits passively
(``OMP_WAIT_POLICY=PASSIVE`` unless set) and onnxruntime does not spin. Run from the
repository root:

``python benchmarks/bench_projection.py [--threads N] [--seconds S] [--quick] [--out FILE]``
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

if __name__ == "__main__":
    # Before torch starts its OpenMP pool: a pool that spins after its call keeps a core
    # from the next library's pool, and the timings snap to the scheduler's time slices.
    # A script imported by the tests leaves the variable alone.
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    if not __package__:
        # Run as ``python benchmarks/bench_projection.py``: the benchmarks import as a package.
        sys.path[0] = str(Path(__file__).resolve().parents[1])

import tempfile
import warnings
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np
import torch

from benchmarks._record import check_out, command_line, format_table, parser, record_path, table, write_record
from benchmarks._timing import median_seconds
from torch_eigview import EigenProjection
from torch_eigview.io import export_projection

IMAGE_SHAPE = (1, 128, 128)
METHODS = ("eager", "compile", "ort-plain", "ort", "sklearn")


def make_projection(k: int, seed: int = 0) -> EigenProjection:
    """A random orthonormal (k, 16384) basis and mean as an :class:`EigenProjection`."""
    gen = torch.Generator().manual_seed(seed)
    n = int(np.prod(IMAGE_SHAPE))
    basis, _ = torch.linalg.qr(torch.randn(n, k, generator=gen, dtype=torch.float64))
    mean = torch.rand(n, generator=gen, dtype=torch.float64)
    return EigenProjection.from_tensors(mean.float(), basis.T.contiguous().float(), image_shape=IMAGE_SHAPE)


def sklearn_pca(projection: EigenProjection) -> Any:
    """A fitted ``sklearn.decomposition.PCA`` whose ``components_`` and ``mean_`` are the projection's."""
    from sklearn.decomposition import PCA

    k, n = projection.n_components, projection.in_features
    pca = PCA(n_components=k).fit(np.random.default_rng(0).random((k + 1, n), dtype=np.float32))
    pca.components_ = projection.components.numpy().copy()
    pca.mean_ = projection.mean.numpy().copy()
    pca.whiten = False
    return pca


def session(path: str, threads: int | None) -> Any:
    """An onnxruntime CPU session that does not spin; tuned (threads, all optimizations) when
    ``threads`` is given."""
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    if threads is not None:
        options.intra_op_num_threads = threads
        options.graph_optimization_level = onnxruntime.GraphOptimizationLevel.ORT_ENABLE_ALL
    return onnxruntime.InferenceSession(path, options, providers=["CPUExecutionProvider"])


def bench_projection(
    ks: Sequence[int], batches: Sequence[int], threads: int, budget: float, backend: str
) -> list[dict[str, Any]]:
    """Images per second of every method for every k and batch, after checking that all agree."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in ks:
            projection = make_projection(k).eval()
            compiled = torch.compile(projection, backend=backend)
            plain_path, folded_path = os.path.join(tmp, f"plain{k}.onnx"), os.path.join(tmp, f"fold{k}.onnx")
            export_projection(projection, plain_path, fold=False)
            export_projection(projection, folded_path)
            ort_plain, ort = session(plain_path, None), session(folded_path, threads)
            pca = sklearn_pca(projection)
            for batch in batches:
                x = torch.rand(batch, *IMAGE_SHAPE, generator=torch.Generator().manual_seed(batch))
                xn, xflat = x.numpy(), x.flatten(1).numpy()
                want = pca.transform(xflat)
                with torch.inference_mode():
                    for got in (projection(x).numpy(), compiled(x).numpy(), ort.run(None, {"images": xn})[0]):
                        if np.abs(got - want).max() > 1e-4 * np.abs(want).max():
                            raise AssertionError(
                                f"k={k}, batch={batch}: a method disagrees with PCA.transform"
                            )
                    calls: dict[str, Callable[[], object]] = {
                        "eager": partial(projection, x),
                        "compile": partial(compiled, x),
                        "ort-plain": partial(ort_plain.run, None, {"images": xn}),
                        "ort": partial(ort.run, None, {"images": xn}),
                        "sklearn": partial(pca.transform, xflat),
                    }
                    rate = {m: batch / median_seconds(calls[m], budget) for m in METHODS}
                rows.append({"k": k, "batch": batch, "images_per_s": rate})
                print(
                    f"k={k} batch={batch}: " + ", ".join(f"{m} {rate[m]:.0f}/s" for m in METHODS), flush=True
                )
    return rows


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser(__file__, __doc__, "k = 15, batches 1 and 32, 0.05 s per entry, the aot_eager compile backend")
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1, help="torch and onnxruntime threads")
    p.add_argument("--seconds", type=float, default=0.5, help="time budget per entry")
    p.add_argument(
        "--compile-backend",
        default=None,
        help="torch.compile's backend (default inductor; aot_eager with --quick, no C++ build)",
    )
    args = p.parse_args(argv)
    out = record_path(args, __file__)
    check_out(p, out)
    if args.threads < 1 or args.seconds <= 0:
        p.error(f"--threads must be >= 1 and --seconds > 0, got {args.threads} and {args.seconds}")
    ks, batches = ([15], [1, 32]) if args.quick else ([15, 64], [1, 32, 256])
    if args.quick:
        args.seconds = 0.05
    backend = args.compile_backend or ("aot_eager" if args.quick else "inductor")
    import onnxruntime

    previous = torch.get_num_threads()
    torch.set_num_threads(args.threads)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rows = bench_projection(ks, batches, args.threads, args.seconds, backend)
    finally:
        torch.set_num_threads(previous)
    t = table(
        f"Projection of {IMAGE_SHAPE[1]}×{IMAGE_SHAPE[2]} images, {args.threads} thread(s), torch.compile "
        f"backend {backend}: images/s (median of repeats), ratios to scikit-learn's PCA.transform",
        ["k", "batch", *(f"{m} /s" for m in METHODS), "eager / sklearn", "ort / sklearn", "ort / eager"],
        [
            [
                r["k"],
                r["batch"],
                *(r["images_per_s"][m] for m in METHODS),
                r["images_per_s"]["eager"] / r["images_per_s"]["sklearn"],
                r["images_per_s"]["ort"] / r["images_per_s"]["sklearn"],
                r["images_per_s"]["ort"] / r["images_per_s"]["eager"],
            ]
            for r in rows
        ],
    )
    print(format_table(t))
    result = {
        "threads": args.threads,
        "backend": backend,
        "onnxruntime": onnxruntime.__version__,
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
        "rows": rows,
    }
    write_record(
        out,
        title="Projection throughput: torch eager, torch.compile, onnxruntime and scikit-learn",
        command=command_line(__file__, argv),
        tables=[t],
        raw={"quick": args.quick, **result},
    )
    return result


if __name__ == "__main__":
    main()
