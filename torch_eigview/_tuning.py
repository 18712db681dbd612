"""Chunk sizes, batch sizes and thresholds that trade memory or start-up cost for speed.

Nothing here changes what the package computes beyond rounding: each value only decides
how a computation is split into calls, or how many threads or processes run it. The
settings that do change results (a solver, an oversampling, the size of a flow's prior)
are parameters of the functions and classes that use them, with their defaults
documented there. Each entry below states its cost model and what stays the same when it
changes, bit for bit or to rounding; the tests set some of them to tiny values
(``monkeypatch.setattr(_tuning, ...)``) and compare with the default.

The modules read these values at call time (``import torch_eigview._tuning as _tuning``,
then ``_tuning.NAME``), so such a patch takes effect. This module imports nothing: every
layer of the package may read it.

Flows:

- :data:`COST_CHUNK_CPU`, :data:`COST_CHUNK`: the row matcher's cost volume is built a
  slice of labels at a time, each slice one ``grid_sample`` call and its patch costs. On
  the CPU a slice of 2^19 float32 elements (2 MiB) keeps the sampled features, their
  differences and the patch sums in a core's cache between the passes that read them;
  on a GPU, where the cost is per kernel launch, slices of 2^24 elements (64 MiB) make
  few launches. Each label's cost is computed on its own: the same volume bit for bit
  whatever the slicing.
- :data:`FLOW_BATCH_CPU`: on the CPU one row-matcher (or guided-flow) call of
  :func:`~torch_eigview.synthesis.object_geometries` takes the seed pairs whose cost
  volumes, both directions, hold at most 2^22 elements: 5 pairs of 128 × 128 views at
  α = 10° (25 labels), 9 at 5°, one at 45°. A call pays a fixed Python and dispatch cost
  per tensor operation whatever its batch (thousands of operations for the guided flow
  of one pair), and worker threads pay it in turn under the GIL; batching pairs pays it
  once per batch. The matcher holds a few volumes at once, so the batch bounds a call's
  memory to a few times 16 MiB. Each pair of a batch is matched on its own: the same
  correspondences bit for bit.

Eigenspaces:

- :data:`CHUNK_VIEWS`: a streamed fit gathers consecutive blocks of centred views into
  chunks of up to 256 views before each product with the panel (Gram path) or the
  iteration's block (subspace path). A matrix product's speed grows with its smaller side
  until the BLAS kernel's blocking is filled: one object's 41 rows leave much of it
  empty, 256 fill it. A chunk holds 256·N values (16 MiB for N = 16,384 in float32).
  The Gram matrix's entries are the same dot products whatever the chunking; sums over
  chunks (the subspace iteration's Xcᵀ W) agree to rounding.

Rendering:

- :data:`MARCH_BATCH`: the renderer's coarse march evaluates the implicit function at
  angles × rays × steps samples; the angles of a call go through it in groups of at most
  2^20 samples, so that its temporaries (a few float32 and bool arrays of that size, a
  few MiB each) do not grow with the number of angles while a group still amortizes the
  torch calls of a step over many views. Every ray goes through the same operations:
  the same renders bit for bit.

Parallelism (the ``eigview`` commands' policy; a library call runs as its caller set
it up). Each view and each product is computed by the same operations whatever runs it;
only a matrix product that a BLAS splits over a different number of threads may differ
in its last bits.

- :data:`THREADS_DEFAULT`: the commands' intra-op threads. The flow, the map building
  and the warp are many small operations on tensors of a few MB: a second OpenMP thread
  halves each operation's little work but adds a barrier to it, and beside a process
  that keeps the cores busy the team waits at every barrier for its descheduled thread.
  One thread per process never waits for another; the parallelism that pays is over
  objects (:data:`GROUP_OBJECTS`, :data:`PARALLEL_PIXELS`).
- :data:`PRODUCT_FLOPS`: the exception is a large matrix product (the Gram matrix of
  thousands of views), which the commands run on the CPUs other processes leave idle,
  sampled for a tenth of a second first. Below 10^11 floating-point operations, a few
  tenths of a second on one core at the peak GEMM rate of current CPUs and more at any
  lower rate, the sample would cost a large share of what a second thread can save.
- :data:`PARALLEL_PIXELS`: worker *processes* start only for at least 5·10^7
  synthesized pixels (about 3,000 views of 128 × 128). A worker's start is a fresh
  interpreter that imports torch, kornia and scikit-image, on the order of the
  synthesis of a thousand such views (both are CPU work, so the ratio carries across
  machines): from the threshold on, the workers' share of the synthesis repays their
  start; below it one process does as well. Worker threads cost nothing to start and
  have no threshold.
- :data:`GROUP_OBJECTS`: at most 8 objects share one job: their seed pairs' flows go in
  shared calls (:data:`FLOW_BATCH_CPU`), and a job's views are held until it returns, so
  the group bounds the memory of the jobs in flight. A call's fixed cost shared by n
  objects falls as 1/n, so the first few objects of a call take most of the gain; eight
  let 20 objects go to two workers as four equal jobs. The objects' views are those of
  each object alone.
- :data:`GROUP_BYTES`: a job's synthesized views (gallery and held-out, of all its
  objects) stay within 64 MiB where one object's allow it: with two jobs in flight per
  worker, a fit's synthesis then holds a few hundred MiB whatever the objects' number, while
  the flows of a few small objects (COIL's 41 views of 128 × 128, 2.7 MiB each) still go in
  shared calls. A large object (360 views of 3 × 128 × 128, 70 MiB) gets a job of its own.

Whether another value does better on a given machine is for the benchmarks
(``benchmarks/bench_*.py`` in the repository) to show; their figures
belong to that machine, not to this file.
"""

from __future__ import annotations

__all__ = [
    "CHUNK_VIEWS",
    "COST_CHUNK",
    "COST_CHUNK_CPU",
    "FLOW_BATCH_CPU",
    "GROUP_BYTES",
    "GROUP_OBJECTS",
    "MARCH_BATCH",
    "PARALLEL_PIXELS",
    "PRODUCT_FLOPS",
    "THREADS_DEFAULT",
]

#: Elements (labels × pixels × features) of one slice of the row matcher's cost volume
#: on the CPU.
COST_CHUNK_CPU = 1 << 19
#: The same on any other device (a GPU).
COST_CHUNK = 1 << 24
#: Cost-volume elements (both directions of every pair) of one batched row-matcher or
#: guided-flow call over objects on the CPU.
FLOW_BATCH_CPU = 1 << 22
#: Centred views per chunk of a streamed fit's products.
CHUNK_VIEWS = 256
#: Samples (angles × rays × steps) of the renderer's coarse march per group of angles.
MARCH_BATCH = 1 << 20
#: Intra-op threads of an ``eigview`` command unless ``--threads`` says otherwise.
THREADS_DEFAULT = 1
#: Floating-point operations from which a command's matrix product samples the idle CPUs.
PRODUCT_FLOPS = 1e11
#: Synthesized pixels (views × H × W over all objects) from which the commands start
#: worker processes.
PARALLEL_PIXELS = 5e7
#: The most objects of one synthesis job of the commands.
GROUP_OBJECTS = 8
GROUP_BYTES = 64 << 20
