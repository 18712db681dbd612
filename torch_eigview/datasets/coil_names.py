"""What a COIL file name says: ``obj{O}__{P}.png`` files, and the pose each names.

COIL-20 ("processed") names pose ``P`` by its index, 5° apart; COIL-100 names it in
degrees. :func:`resolve_pose_unit` tells the two apart, :func:`pose_files` turns the files
into each object's views by angle, and a folder of indices that looks like a whole
turntable at another step warns (:class:`PoseStepWarning`). :class:`~torch_eigview.datasets.coil.CoilFolder`
reads folders with them.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

from torch_eigview.check import check_number
from torch_eigview.io.images import check_regular_file

__all__ = [
    "ANGLE_TOL",
    "FILE_RE",
    "INDEX_STEP",
    "N_INDEX_POSES",
    "POSE_UNITS",
    "PoseStepWarning",
    "check_pose_step",
    "pose_files",
    "resolve_pose_unit",
    "scan_files",
    "warn_whole_circle",
]

# re.ASCII: ``\d`` alone would also accept non-ASCII digits such as "obj١__0.png".
FILE_RE = re.compile(r"obj([0-9]+)__([0-9]+)\.png", re.ASCII)
POSE_UNITS = ("auto", "index", "degrees")
N_INDEX_POSES = 72  # COIL-20: pose indices 0..71, 5 degrees apart
INDEX_STEP = 5.0  # COIL-20: degrees between consecutive pose indices
ANGLE_TOL = 1e-6  # degrees


def scan_files(root: Path) -> list[tuple[int, int, Path]]:
    """``(object, pose, path)`` of the COIL-named files of ``root``.

    Every name that matches is checked with ``os.stat`` (never opened): a FIFO, a device, a
    folder or a symlink loop named like an image is an error that names them all, not a file
    silently left out of the data set.
    """
    found, bad = [], []
    for p in root.iterdir():
        m = FILE_RE.fullmatch(p.name)
        if m is None:
            continue
        try:
            check_regular_file(p, "COIL file")
        except ValueError as exc:
            bad.append(str(exc))
            continue
        found.append((int(m.group(1)), int(m.group(2)), p))
    if bad:
        listed = "; ".join(sorted(bad)[:5]) + (f"; ... ({len(bad)} in all)" if len(bad) > 5 else "")
        raise ValueError(f"root={str(root)!r} holds COIL-named entries that are not image files: {listed}")
    return found


def resolve_pose_unit(found: list[tuple[int, int, Path]]) -> str:
    """``pose_unit="auto"``: each object's own poses say "degrees" (some P >= 72) or "index"
    (all P < 72); objects that disagree are an error naming the files, so that one stray
    ``obj1__72.png`` cannot turn a COIL-20 folder's indices into degrees."""
    highest: dict[int, int] = {}
    for obj, pose, _ in found:
        highest[obj] = max(highest.get(obj, 0), pose)
    degree_objects = {obj for obj, top in highest.items() if top >= N_INDEX_POSES}
    if not degree_objects:
        return "index"
    if len(degree_objects) == len(highest):
        return "degrees"
    strays = sorted(p.name for obj, pose, p in found if pose >= N_INDEX_POSES)
    listed = ", ".join(strays[:5]) + (f", ... ({len(strays)} files)" if len(strays) > 5 else "")
    index_objects = sorted(set(highest) - degree_objects)
    raise ValueError(
        f"the folder mixes pose conventions: objects {sorted(degree_objects)[:10]} have poses P >= "
        f"{N_INDEX_POSES} (degrees, COIL-100) in {listed}, while objects {index_objects[:10]} have only "
        f"P < {N_INDEX_POSES} (indices, COIL-20); remove the stray files or pass pose_unit='index' or "
        "'degrees' (eigview coil --pose-unit)"
    )


class PoseStepWarning(UserWarning):
    """Pose indices read with COIL-20's 5° step that look like a whole turntable at another
    step: every object has the views ``0 … N − 1``, 3 <= N < 72 (see ``CoilFolder(pose_step=)``)."""


def check_pose_step(pose_step: float | None, pose_unit: str) -> float | None:
    """``pose_step`` checked: None, or a finite number of degrees in (0, 360] for index poses."""
    if pose_step is None:
        return None
    step = check_number(pose_step, "pose_step")
    if not (math.isfinite(step) and 0 < step <= 360):
        raise ValueError(f"pose_step must be a number of degrees in (0, 360], got {pose_step!r}")
    if pose_unit == "degrees":
        raise ValueError(
            f"pose_step={pose_step!r} is the step between pose indices, so it needs pose_unit='index' "
            "or 'auto', got pose_unit='degrees' (its file poses are degrees already)"
        )
    return float(step)


def warn_whole_circle(root: Path, files: dict[int, dict[float, Path]]) -> None:
    """A :class:`PoseStepWarning` where every object holds the indices 0 … N − 1, 3 <= N < 72
    (fewer than three views round a turntable are 180° apart or a single view):
    read 5° apart they cover 0 … 5·(N − 1)°, the first part of COIL-20's circle, while N
    views of a turntable named by index are 360 / N degrees apart; nothing in the files
    tells the two apart."""
    counts = {len(views) for views in files.values()}
    if len(counts) != 1:
        return
    n = counts.pop()
    expected = {INDEX_STEP * i for i in range(n)}
    if not 3 <= n < N_INDEX_POSES or any(set(views) != expected for views in files.values()):
        return
    warnings.warn(
        f"{root}: every object has the pose indices 0..{n - 1}, read with COIL-20's step of "
        f"{INDEX_STEP:g} degrees as 0..{INDEX_STEP * (n - 1):g} degrees; if the {n} views go once round "
        f"the turntable they are {360 / n:g} degrees apart: pass pose_step={360 / n:g} "
        f"(eigview coil --pose-step {360 / n:g})",
        PoseStepWarning,
        stacklevel=3,
    )


def pose_files(
    found: list[tuple[int, int, Path]], pose_unit: str, step: float
) -> dict[int, dict[float, Path]]:
    """Each object's files by angle (``step`` · P degrees) from the ``(object, P, path)`` of
    :func:`scan_files`, for ``pose_unit`` "index" or "degrees" (``step`` 1).

    Raises:
        ValueError: a P at or past 360 degrees, or two files naming the same view.
    """
    limit = math.ceil(360 / step - ANGLE_TOL) if pose_unit == "index" else 360
    files: dict[int, dict[float, Path]] = {}
    for obj, p, path in sorted(found):
        if p >= limit:
            raise ValueError(
                f"pose_unit={pose_unit!r} with {step:g} degrees a pose needs P in 0..{limit - 1} "
                f"(angles in [0, 360)), got {path}"
            )
        views = files.setdefault(obj, {})
        if step * p in views:
            raise ValueError(f"{path} and {views[step * p]} name the same view (object {obj})")
        views[step * p] = path
    return files
