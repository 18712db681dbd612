"""Timing helpers of the benchmarks: wall-clock seconds with ``time.perf_counter``."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import torch

__all__ = ["best_of", "clock", "interleaved_medians", "median_seconds"]


def best_of(fn: Callable[[], object], repeats: int) -> float:
    """The least seconds of ``repeats`` calls after one warm-up call (first-call allocations,
    kernel selection): the figure least disturbed by other work on the machine."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def interleaved_medians(fns: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median seconds of each function, the functions alternating within every repeat, so
    that a change of load on the machine hits all of them."""
    for fn in fns.values():
        fn()  # warm-up
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return {name: statistics.median(ts) for name, ts in times.items()}


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


def clock(device: torch.device) -> float:
    """``time.perf_counter`` once the device's queued work is done (CUDA runs asynchronously)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()
