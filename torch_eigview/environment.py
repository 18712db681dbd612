"""What a result was measured with: package versions, the machine and the source revision.

:func:`environment_info` is what a bug report or a results file records beside its
figures (as scikit-learn's ``show_versions`` and ``torch.utils.collect_env`` do): the
versions of Python and of the packages the library uses, the CPU model and the number
of CPUs this process may use, the CUDA devices torch sees, and, when the package runs
from a git checkout, the commit and whether the tree had uncommitted changes. Nothing
here imports torch before it is asked for.
"""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
import sys
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

__all__ = ["environment_info", "package_version"]

#: The distributions whose versions :func:`environment_info` reports.
PACKAGES = (
    "torch_eigview",
    "torch",
    "kornia",
    "numpy",
    "scipy",
    "scikit-image",
    "onnx",
    "onnxruntime",
    "onnxscript",
    "scikit-learn",
)


def package_version() -> str:
    """This package's installed version, or ``"0+unknown"`` in a source tree that was never
    installed."""
    try:
        return version("torch_eigview")
    except PackageNotFoundError:
        return "0+unknown"


def _cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux), else the platform's processor."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git_revision(start: Path) -> dict[str, Any] | None:
    """The commit of the git checkout that holds ``start``, and whether its tree is dirty,
    or None outside a checkout (an installed wheel) or without git."""
    try:
        top = subprocess.run(
            ["git", "-C", str(start), "rev-parse", "--show-toplevel", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.split()
        dirty = subprocess.run(
            ["git", "-C", top[0], "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError, IndexError):
        return None
    return {"commit": top[1], "dirty": bool(dirty)}


def environment_info(*, devices: bool = True) -> dict[str, Any]:
    """The date, versions, machine and source revision of this run, JSON-ready.

    Args:
        devices: also import torch and list its CUDA devices (their names and memory).

    Returns:
        ``{"date": ISO 8601 UTC, "python", "platform", "packages": {name: version or
        None}, "machine": {"cpu", "cpus", "gpus": [...]}, "source": {"commit", "dirty"} or
        None}``; ``cpus`` counts the CPUs this process may run on.

    Example:
        >>> info = environment_info(devices=False)
        >>> sorted(info)
        ['date', 'machine', 'packages', 'platform', 'python', 'source']
    """
    packages: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            packages[name] = version(name)
        except PackageNotFoundError:
            packages[name] = None
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    gpus: list[dict[str, Any]] = []
    if devices:
        import torch

        for i in range(torch.cuda.device_count()):
            props = torch.cuda.get_device_properties(i)
            gpus.append({"name": props.name, "memory_gib": round(props.total_memory / 2**30, 1)})
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "packages": packages,
        "machine": {"cpu": _cpu_model(), "cpus": cpus, "gpus": gpus},
        "source": _git_revision(Path(__file__).resolve().parent),
    }
