"""Projection throughput (images/s): torch eager, torch.compile, onnxruntime, sklearn PCA.

Not a test: a benchmark to run by hand. For 128×128 images, k = 15 and 64, batches 1, 32
and 256, it times the same basis in

- ``eager``: :class:`~torch_eigview.EigenProjection` under ``torch.inference_mode``;
- ``compile``: the same module through ``torch.compile`` (inductor);
- ``ort-plain``: onnxruntime on the projection's ``forward`` as written (Sub, MatMul),
  default session options (but no spinning, as for every session here);
- ``ort``: onnxruntime on the folded graph ``z = x @ Wᵀ − mean @ Wᵀ``
  (:func:`torch_eigview.io.onnx.export_projection`), ``intra_op_num_threads`` = the torch
  threads, all graph optimizations;
- ``sklearn``: ``PCA.transform`` with ``components_`` and ``mean_`` set to the same basis
  (the reference of the ratios).

Each entry is the median of repeated calls after warm-up runs. Run:
``python export/bench_projection.py [--threads N] [--seconds S]``
"""

from __future__ import annotations

import os

# Three libraries share the cores here (torch's OpenMP pool, numpy's BLAS pool, onnxruntime's
# pool); a pool that spin-waits after its call starves the next one (on 2 cores the timings
# then snap to 4 ms scheduler slices). Passive waiting for OpenMP, no spinning in onnxruntime.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse
import statistics
import tempfile
import time
import warnings
from collections.abc import Callable
from functools import partial

import numpy as np
import onnxruntime
import torch
from sklearn.decomposition import PCA

from torch_eigview import EigenProjection
from torch_eigview.io.onnx import export_projection

IMAGE_SHAPE = (1, 128, 128)
BATCHES = (1, 32, 256)
KS = (15, 64)
METHODS = ("eager", "compile", "ort-plain", "ort", "sklearn")


def median_seconds(fn: Callable[[], object], budget: float, warmup: int = 3) -> float:
    """Median seconds per call over repeats filling about ``budget`` seconds (5 at least)."""
    for _ in range(warmup):
        fn()
    times: list[float] = []
    start = time.perf_counter()
    while len(times) < 5 or (time.perf_counter() - start < budget and len(times) < 2000):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def make_projection(k: int, seed: int = 0) -> EigenProjection:
    gen = torch.Generator().manual_seed(seed)
    n = int(np.prod(IMAGE_SHAPE))
    basis, _ = torch.linalg.qr(torch.randn(n, k, generator=gen, dtype=torch.float64))
    mean = torch.rand(n, generator=gen, dtype=torch.float64)
    return EigenProjection(mean.float(), basis.T.contiguous().float(), image_shape=IMAGE_SHAPE)


def sklearn_pca(projection: EigenProjection) -> PCA:
    k, n = projection.n_components, projection.in_features
    pca = PCA(n_components=k).fit(np.random.default_rng(0).random((k + 1, n), dtype=np.float32))
    pca.components_ = projection.components.numpy().copy()
    pca.mean_ = projection.mean.numpy().copy()
    pca.whiten = False
    return pca


def session(path: str, threads: int | None) -> onnxruntime.InferenceSession:
    options = onnxruntime.SessionOptions()
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    if threads is not None:
        options.intra_op_num_threads = threads
        options.graph_optimization_level = onnxruntime.GraphOptimizationLevel.ORT_ENABLE_ALL
    return onnxruntime.InferenceSession(path, options, providers=["CPUExecutionProvider"])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--seconds", type=float, default=0.5, help="time budget per entry")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    warnings.filterwarnings("ignore")
    print(
        f"torch {torch.__version__} ({torch.get_num_threads()} threads), onnxruntime "
        f"{onnxruntime.__version__}, images {IMAGE_SHAPE}, median of repeats after warm-up"
    )
    header = f"{'k':>3} {'batch':>5} " + " ".join(f"{m:>10}" for m in METHODS)
    header += f" {'ort/sklearn':>11} {'ort/eager':>9}"
    rows = [header, "-" * len(header)]
    with tempfile.TemporaryDirectory() as tmp:
        for k in KS:
            projection = make_projection(k).eval()
            compiled = torch.compile(projection)
            plain_path, folded_path = os.path.join(tmp, f"plain{k}.onnx"), os.path.join(tmp, f"fold{k}.onnx")
            export_projection(projection, plain_path, fold=False)
            export_projection(projection, folded_path)
            ort_plain, ort = session(plain_path, None), session(folded_path, args.threads)
            pca = sklearn_pca(projection)
            for batch in BATCHES:
                x = torch.rand(batch, *IMAGE_SHAPE, generator=torch.Generator().manual_seed(batch))
                xn, xflat = x.numpy(), x.flatten(1).numpy()
                want = pca.transform(xflat)
                with torch.inference_mode():
                    for got in (projection(x).numpy(), compiled(x).numpy(), ort.run(None, {"images": xn})[0]):
                        assert np.abs(got - want).max() <= 1e-4 * np.abs(want).max()
                    calls: dict[str, Callable[[], object]] = {
                        "eager": partial(projection, x),
                        "compile": partial(compiled, x),
                        "ort-plain": partial(ort_plain.run, None, {"images": xn}),
                        "ort": partial(ort.run, None, {"images": xn}),
                        "sklearn": partial(pca.transform, xflat),
                    }
                    rate = {m: batch / median_seconds(calls[m], args.seconds) for m in METHODS}
                rows.append(
                    f"{k:>3} {batch:>5} "
                    + " ".join(f"{rate[m]:>10.0f}" for m in METHODS)
                    + f" {rate['ort'] / rate['sklearn']:>10.2f}x {rate['ort'] / rate['eager']:>8.2f}x"
                )
                print(rows[-1], flush=True)
    print("\nimages/s; ratios are ort (folded, tuned session) over sklearn PCA.transform and torch eager")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
