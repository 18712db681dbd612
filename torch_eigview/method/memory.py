"""How much memory a fit will take, how much this process can still have, and the check
that stops a fit before any work when the first exceeds the second.

A fit killed by the operating system halfway through says nothing and loses everything;
one refused before it starts says what it needed. :func:`available_memory` takes the
tightest of the bounds that apply to this process: the machine's available memory
(``MemAvailable``), a cgroup's memory limit (a container's), and the address-space and
data-segment limits (``ulimit -v``, ``ulimit -d``) less what the process already maps.
:func:`check_memory` compares an estimate with it and raises :class:`MemoryBudgetError`,
which names the sizes that drive the estimate.
"""

from __future__ import annotations

import resource
from dataclasses import dataclass

__all__ = [
    "MemoryBudgetError",
    "MemoryEstimate",
    "available_memory",
    "check_memory",
    "fit_estimate",
    "process_rss",
]

GIB = 1 << 30


@dataclass(frozen=True)
class MemoryEstimate:
    """A fit's peak memory, estimated before it starts.

    Attributes:
        bytes: the peak, beyond what the process holds already.
        objects: the objects to fit.
        views: gallery views per object (the largest object's).
        held_out: views per object synthesized to calibrate rejection.
        pixels: values per view, C·H·W.
        image_shape: (C, H, W) of a view.
        components: k (or the energy fraction asked for).
        incremental: the fit merges its views block by block (memory bounded by a block
            and the model), rather than holding every view.
    """

    bytes: int
    objects: int
    views: int
    held_out: int
    pixels: int
    image_shape: tuple[int, int, int]
    components: int | float
    incremental: bool

    def describe(self) -> str:
        c, h, w = self.image_shape
        held = f" and {self.held_out} held out for rejection" if self.held_out else ""
        how = "merged block by block" if self.incremental else "held all at once"
        return (
            f"{self.objects} objects x {self.views} views{held} of (C, H, W)=({c}, {h}, {w}), "
            f"k={self.components:g}, {how}"
        )


class MemoryBudgetError(ValueError):
    """A fit would need more memory than this process can have (refused before any work).

    Attributes:
        estimate: what the fit would need.
        available: the bytes available.
        bound: what bounds them (the machine, a container, ``ulimit -v``).
    """

    def __init__(self, estimate: MemoryEstimate, available: int, bound: str, remedies: str) -> None:
        self.estimate, self.available, self.bound = estimate, available, bound
        super().__init__(
            f"the fit needs about {estimate.bytes / GIB:.2f} GiB ({estimate.describe()}) but only "
            f"{available / GIB:.2f} GiB are available ({bound}); {remedies}"
        )


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_available() -> int | None:
    """A cgroup v2 memory limit less its usage, where this process is in one."""
    try:
        with open("/sys/fs/cgroup/memory.max", encoding="ascii") as fh:
            limit = fh.read().strip()
        if limit == "max":
            return None
        with open("/sys/fs/cgroup/memory.current", encoding="ascii") as fh:
            used = int(fh.read().strip())
        return int(limit) - used
    except (OSError, ValueError):
        return None


def _status_kib(field: str) -> int | None:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return None


def available_memory() -> tuple[int, str]:
    """The bytes this process can still allocate, and what bounds them.

    Returns:
        ``(bytes, bound)``: the tightest of the machine's available memory, a container's
        limit, and the ``ulimit -v`` / ``ulimit -d`` limits less what the process maps;
        where none can be read (no ``/proc``), a very large number.

    Example:
        >>> free, bound = available_memory()
        >>> free > 0 and isinstance(bound, str)
        True
    """
    found: list[tuple[int, str]] = []
    meminfo = _meminfo_available()
    if meminfo is not None:
        found.append((meminfo, "the machine's available memory"))
    cgroup = _cgroup_available()
    if cgroup is not None:
        found.append((cgroup, "the container's memory limit"))
    for limit_id, field, name in (
        (resource.RLIMIT_AS, "VmSize", "the address-space limit, ulimit -v"),
        (resource.RLIMIT_DATA, "VmData", "the data-segment limit, ulimit -d"),
    ):
        soft, _ = resource.getrlimit(limit_id)
        used = _status_kib(field)
        if soft != resource.RLIM_INFINITY and used is not None:
            found.append((soft - used * 1024, name))
    if not found:
        return 1 << 62, "no limit could be read"
    free, bound = min(found)
    return max(free, 0), bound


def check_memory(estimate: MemoryEstimate, remedies: str, *, margin: float = 1.1) -> None:
    """Raises :class:`MemoryBudgetError` when ``estimate`` (times ``margin``, for what the
    estimate leaves out) exceeds :func:`available_memory`.

    Args:
        estimate: the fit's peak.
        remedies: what the caller can change, for the message (the command names its
            flags, the estimator its parameters).
        margin: the factor on the estimate.
    """
    free, bound = available_memory()
    if estimate.bytes * margin > free:
        raise MemoryBudgetError(estimate, free, bound, remedies)


def process_rss() -> int:
    """This process's resident set in bytes (0 where ``/proc`` cannot tell)."""
    rss = _status_kib("VmRSS")
    return 0 if rss is None else rss * 1024


def fit_estimate(
    *,
    objects: int,
    views: int,
    held_out: int,
    image_shape: tuple[int, int, int],
    itemsize: int,
    components: int | float,
    max_views: int,
    max_rank: int,
    kernel: bool,
    workers: int,
) -> MemoryEstimate:
    """The peak of a :class:`~torch_eigview.method.FewViewEigenspace` fit, from its sizes.

    The terms, in bytes (N = C·H·W values a view, P the gallery's views):

    - held at once (P <= ``max_views``, or a kernel): the views and their unit-norm copy
      (2·P·N·itemsize), the Gram or scatter matrix (min(P, N)²·8; a kernel's P²·8 three
      times over) and the held-out views;
    - merged: a merge block of ``max_rank`` views plus an object's, as data and in float64,
      the model's basis three times over (its own, the next and a product: 3·N·max_rank·8),
      the gallery's coordinates (P·max_rank·8) and at most ``max_views // 4`` held-out views;
    - in both, each worker's object in flight: its gallery and held-out views three times
      over (the views, the warp's maps and the blend).
    """
    c, h, w = image_shape
    n = c * h * w
    p = objects * views
    in_flight = max(1, workers) * (views + held_out) * n * itemsize * 3
    merged = not kernel and p > max_views
    if merged:
        block = (max_rank + views) * n
        held = min(objects * held_out, max(1, max_views // 4)) * n * itemsize
        total = block * (itemsize + 8) + 3 * n * max_rank * 8 + p * max_rank * 8 + held
    else:
        gram = 3 * p * p * 8 if kernel else min(p, n) ** 2 * 8
        total = 2 * p * n * itemsize + gram + objects * held_out * n * itemsize
    return MemoryEstimate(
        bytes=int(total + in_flight),
        objects=objects,
        views=views,
        held_out=held_out,
        pixels=n,
        image_shape=image_shape,
        components=components,
        incremental=merged,
    )
