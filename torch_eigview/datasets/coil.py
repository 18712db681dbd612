"""Loading COIL-style turntable images (``obj{O}__{P}.png``) as tensors.

COIL-20 ("processed") names pose ``P`` by its index (the view at ``5·P`` degrees); COIL-100
uses the same layout with ``P`` in degrees. A turntable of other views named by index
(``obj1__0.png`` … ``obj1__35.png`` every 10°) gives its step as ``pose_step``.
:class:`CoilFolder` scans a folder once, reads files lazily with
:func:`~torch_eigview.io.images.read_image` and caches the decoded pixels.
"""

from __future__ import annotations

import math
import numbers
import operator
import os
import re
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import torch

from torch_eigview.check import as_angle_tensor, check_choice, check_limit, check_number
from torch_eigview.io.images import check_regular_file, read_image, to_unit_float

__all__ = [
    "DATA_ENV",
    "CoilFolder",
    "PoseStepWarning",
    "default_data_root",
    "find_coil_root",
    "parse_object_spec",
]

#: The environment variable naming the folder that holds the data sets (``coil-20-proc/``, …).
DATA_ENV = "TORCH_EIGVIEW_DATA"

# re.ASCII: ``\d`` alone would also accept non-ASCII digits such as "obj١__0.png".
_FILE_RE = re.compile(r"obj([0-9]+)__([0-9]+)\.png", re.ASCII)
_SPEC_RE = re.compile(r"\s*([0-9]+)\s*(?:-\s*([0-9]+)\s*)?", re.ASCII)
_POSE_UNITS = ("auto", "index", "degrees")
_N_INDEX_POSES = 72  # COIL-20: pose indices 0..71, 5 degrees apart
_INDEX_STEP = 5.0  # COIL-20: degrees between consecutive pose indices
_ANGLE_TOL = 1e-6  # degrees
# A source checkout keeps its data beside it, in ../shared/data (this file is
# <checkout>/torch_eigview/datasets/coil.py); an installed copy has no such folder.
_CHECKOUT_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def default_data_root() -> Path:
    """The folder that holds the data sets: ``$TORCH_EIGVIEW_DATA``, else ``../shared/data`` beside the checkout.

    An empty ``TORCH_EIGVIEW_DATA`` counts as unset. The folder need not exist.
    """
    env = os.environ.get(DATA_ENV, "")
    return Path(env).expanduser() if env else _CHECKOUT_DATA


def find_coil_root(root: str | os.PathLike[str] | None = None, name: str = "coil-20-proc") -> Path:
    """The folder of COIL images to read: ``root`` when given, else ``default_data_root() / name``.

    The precedence is the commands' and examples': their ``--root`` flag, then the
    ``TORCH_EIGVIEW_DATA`` environment variable (a folder holding ``coil-20-proc/``), then
    ``../shared/data/coil-20-proc`` beside the checkout.

    Args:
        root: The COIL folder itself (``obj{O}__{P}.png`` files), or None for the default.
        name: The folder under the data root when ``root`` is None (``"coil-20-proc"``
            for the processed COIL-20, e.g. ``"coil-100"`` for COIL-100).

    Returns:
        The folder; it exists (whether it holds COIL files, :class:`CoilFolder` checks).

    Raises:
        TypeError: ``root`` is not a path or ``name`` not a str.
        ValueError: The folder does not exist; the message says which folder was looked
            for, why there, and the three ways to point at the images.
    """
    if root is not None and not isinstance(root, (str, os.PathLike)):
        raise TypeError(f"root must be a str, a path or None, got {type(root).__name__}")
    if not isinstance(name, str):
        raise TypeError(f"name must be a str such as 'coil-20-proc', got {type(name).__name__}")
    path = Path(root) if root is not None else default_data_root() / name
    if path.is_dir():
        return path
    if root is not None:
        source = "given with --root"
    elif os.environ.get(DATA_ENV):
        source = f"from {DATA_ENV}={os.environ[DATA_ENV]}"
    else:
        source = f"the default, {DATA_ENV} being unset"
    raise ValueError(
        f"COIL images not found: root={str(path)!r} ({source}) must be an existing directory of "
        f"obj{{O}}__{{P}}.png images. Put the {name}/ folder in {default_data_root()}, or set "
        f"{DATA_ENV} to the folder that holds {name}/, or pass the folder itself with --root DIR."
    )


# Object ids one selection may name (COIL-100 has 100).
OBJECT_LIMIT = ("EIGVIEW_MAX_OBJECTS", 100_000)


def parse_object_spec(spec: str) -> list[int]:
    """Parses an object selection such as ``"1-20"``, ``"1,3,5-7"`` or ``"4"``.

    Args:
        spec: Comma-separated positive integers or inclusive ranges ``a-b`` with ``a <= b``.

    Returns:
        The selected object ids, sorted and without duplicates.

    Raises:
        TypeError: ``spec`` is not a string.
        ValueError: ``spec`` is empty, malformed, holds 0 or a reversed range, or names more
            ids than ``EIGVIEW_MAX_OBJECTS`` (default 100,000).
    """
    if not isinstance(spec, str):
        raise TypeError(f"spec must be a string such as '1-20' or '1,3,5-7', got {type(spec).__name__}")
    ids: set[int] = set()
    for token in spec.split(","):
        m = _SPEC_RE.fullmatch(token)
        if m is None:
            raise ValueError(f"spec={spec!r} must look like '1-20' or '1,3,5-7' (bad part {token!r})")
        lo = int(m.group(1))
        hi = lo if m.group(2) is None else int(m.group(2))
        if lo < 1:
            raise ValueError(f"spec={spec!r} must hold positive object ids, got {lo}")
        if hi < lo:
            raise ValueError(f"spec={spec!r} holds the reversed range {lo}-{hi} (must be low-high)")
        # Bounded before the set is built: "1-99999999999" would fill the memory.
        check_limit(len(ids) + hi - lo + 1, f"spec={spec!r}", "object ids", *OBJECT_LIMIT)
        ids.update(range(lo, hi + 1))
    return sorted(ids)


def _scan(root: Path) -> list[tuple[int, int, Path]]:
    """``(object, pose, path)`` of the COIL-named files of ``root``.

    Every name that matches is checked with ``os.stat`` (never opened): a FIFO, a device, a
    folder or a symlink loop named like an image is an error that names them all, not a file
    silently left out of the data set.
    """
    found, bad = [], []
    for p in root.iterdir():
        m = _FILE_RE.fullmatch(p.name)
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


def _pose_unit(found: list[tuple[int, int, Path]]) -> str:
    """``pose_unit="auto"``: each object's own poses say "degrees" (some P >= 72) or "index"
    (all P < 72); objects that disagree are an error naming the files, so that one stray
    ``obj1__72.png`` cannot turn a COIL-20 folder's indices into degrees."""
    highest: dict[int, int] = {}
    for obj, pose, _ in found:
        highest[obj] = max(highest.get(obj, 0), pose)
    degree_objects = {obj for obj, top in highest.items() if top >= _N_INDEX_POSES}
    if not degree_objects:
        return "index"
    if len(degree_objects) == len(highest):
        return "degrees"
    strays = sorted(p.name for obj, pose, p in found if pose >= _N_INDEX_POSES)
    listed = ", ".join(strays[:5]) + (f", ... ({len(strays)} files)" if len(strays) > 5 else "")
    index_objects = sorted(set(highest) - degree_objects)
    raise ValueError(
        f"the folder mixes pose conventions: objects {sorted(degree_objects)[:10]} have poses P >= "
        f"{_N_INDEX_POSES} (degrees, COIL-100) in {listed}, while objects {index_objects[:10]} have only "
        f"P < {_N_INDEX_POSES} (indices, COIL-20); remove the stray files or pass pose_unit='index' or "
        "'degrees' (eigview coil --pose-unit)"
    )


class PoseStepWarning(UserWarning):
    """Pose indices read with COIL-20's 5° step that look like a whole turntable at another
    step: every object has the views ``0 … N − 1``, 3 <= N < 72 (see ``CoilFolder(pose_step=)``)."""


def _check_step(pose_step: float | None, pose_unit: str) -> float | None:
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


def _warn_whole_circle(root: Path, files: dict[int, dict[float, Path]]) -> None:
    """A :class:`PoseStepWarning` where every object holds the indices 0 … N − 1, 3 <= N < 72
    (fewer than three views round a turntable are 180° apart or a single view):
    read 5° apart they cover 0 … 5·(N − 1)°, the first part of COIL-20's circle, while N
    views of a turntable named by index are 360 / N degrees apart; nothing in the files
    tells the two apart."""
    counts = {len(views) for views in files.values()}
    if len(counts) != 1:
        return
    n = counts.pop()
    expected = {_INDEX_STEP * i for i in range(n)}
    if not 3 <= n < _N_INDEX_POSES or any(set(views) != expected for views in files.values()):
        return
    warnings.warn(
        f"{root}: every object has the pose indices 0..{n - 1}, read with COIL-20's step of "
        f"{_INDEX_STEP:g} degrees as 0..{_INDEX_STEP * (n - 1):g} degrees; if the {n} views go once round "
        f"the turntable they are {360 / n:g} degrees apart: pass pose_step={360 / n:g} "
        f"(eigview coil --pose-step {360 / n:g})",
        PoseStepWarning,
        stacklevel=3,
    )


class CoilFolder:
    """A folder of COIL-style images ``obj{O}__{P}.png``, read lazily and cached.

    Images come back as float tensors ``(C, H, W)`` in ``[0, 1]``: ``uint8`` is divided by
    255, ``uint16`` by 65535, float images are kept as they are. Grayscale gives ``C = 1``,
    RGB ``C = 3``; an alpha channel is dropped. Every image must have the shape of the first
    one, which is read at construction.

    Args:
        root: The folder; other files in it are ignored.
        pose_unit: ``"index"`` (COIL-20, pose ``P`` is ``5·P`` degrees), ``"degrees"``
            (COIL-100, pose ``P`` is ``P`` degrees) or ``"auto"``: ``"degrees"`` when every
            object has some ``P`` above 71, the largest COIL-20 index, ``"index"`` when none
            has, and an error when the objects disagree (a stray file). A COIL-100 subset
            whose poses all lie below 72 degrees is thus read as indices; pass the unit then.
        pose_step: degrees between consecutive pose indices (``pose_unit`` "index", or
            "auto" resolving to it): default 5, COIL-20's. A folder whose objects all hold
            the indices ``0 … N − 1`` for some 3 <= N < 72 warns (:class:`PoseStepWarning`) when
            the step is not given: N views once round a turntable are ``360 / N`` apart.
        dtype: Floating dtype of the returned tensors.
        device: Device of the returned tensors (files are read and decoded on the CPU).

    Raises:
        TypeError: ``root`` is not a path, ``pose_unit`` not a str or ``dtype`` not a
            floating dtype.
        ValueError: ``root`` is not a folder or holds no COIL file, a COIL-named entry is
            not a regular file (FIFO, device, folder, symlink loop), ``pose_unit`` is
            unknown or "auto" finds mixed conventions, ``pose_step`` is not in (0, 360] or
            comes with ``pose_unit="degrees"``, a pose lies outside ``[0, 360)`` degrees,
            two files name the same view, or the first image cannot be read.
    """

    def __init__(
        self,
        root: str | os.PathLike[str],
        *,
        pose_unit: str = "auto",
        pose_step: float | None = None,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str = "cpu",
    ) -> None:
        if not isinstance(root, (str, os.PathLike)):
            raise TypeError(f"root must be a str or a path, got {type(root).__name__}")
        if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
            raise TypeError(f"dtype must be a floating torch.dtype, got {dtype!r}")
        pose_unit = check_choice(pose_unit, "pose_unit", _POSE_UNITS)
        given_step = _check_step(pose_step, pose_unit)
        self.root = Path(root)
        if not self.root.is_dir():
            raise ValueError(f"root={str(self.root)!r} must be an existing directory")
        found = _scan(self.root)
        if not found:
            raise ValueError(f"root={str(self.root)!r} holds no COIL files (obj{{O}}__{{P}}.png)")
        self.pose_unit = _pose_unit(found) if pose_unit == "auto" else pose_unit
        pose_unit = self.pose_unit
        self.dtype = dtype
        self.device = torch.device(device)
        if pose_unit == "degrees" and given_step is not None:
            raise ValueError(
                f"pose_step={pose_step!r} needs pose files named by index, but the folder's poses "
                "are degrees (some P >= 72; pose_unit 'auto' resolved to 'degrees')"
            )
        #: Degrees between consecutive file poses P.
        self.pose_step = (_INDEX_STEP if given_step is None else given_step) if pose_unit == "index" else 1.0
        step = self.pose_step
        limit = math.ceil(360 / step - _ANGLE_TOL) if pose_unit == "index" else 360
        self._files: dict[int, dict[float, Path]] = {}
        for obj, p, path in sorted(found):
            if p >= limit:
                raise ValueError(
                    f"pose_unit={pose_unit!r} with {step:g} degrees a pose needs P in 0..{limit - 1} "
                    f"(angles in [0, 360)), got {path}"
                )
            views = self._files.setdefault(obj, {})
            if step * p in views:
                raise ValueError(f"{path} and {views[step * p]} name the same view (object {obj})")
            views[step * p] = path
        if pose_unit == "index" and given_step is None:
            _warn_whole_circle(self.root, self._files)
        first_path = min(found)[2]
        first = read_image(first_path)
        c, h, w = first.shape
        self.image_shape: tuple[int, int, int] = (c, h, w)
        self._cache: dict[Path, np.ndarray] = {first_path: first}

    @property
    def objects(self) -> list[int]:
        """The object ids present, sorted."""
        return sorted(self._files)

    def __len__(self) -> int:
        return sum(len(views) for views in self._files.values())

    def __repr__(self) -> str:
        return (
            f"CoilFolder(root={str(self.root)!r}, objects={len(self._files)}, files={len(self)}, "
            f"pose_unit={self.pose_unit!r}, pose_step={self.pose_step:g}, image_shape={self.image_shape})"
        )

    def poses(self, obj: int) -> list[float]:
        """The available pose angles of object ``obj`` in degrees, sorted, in ``[0, 360)``."""
        return sorted(self._views(obj))

    def path(self, obj: int, degrees: float) -> Path:
        """The file of object ``obj``'s view at ``degrees`` (a pose of :meth:`poses`, to 1e-6 degrees)."""
        return self._find(obj, float(check_number(degrees, "degrees")))

    def image(self, obj: int, degrees: float) -> torch.Tensor:
        """Returns the view of object ``obj`` at ``degrees`` (taken modulo 360).

        Args:
            obj: Object id.
            degrees: Turntable angle; must match an available pose to within 1e-6 degrees.

        Returns:
            A new tensor ``(C, H, W)`` of ``self.dtype``, values in ``[0, 1]``.

        Raises:
            TypeError: ``obj`` is not an int or ``degrees`` not a real number.
            ValueError: Unknown object, no file at that angle, or an invalid file.
        """
        if isinstance(degrees, bool) or not isinstance(degrees, numbers.Real):
            raise TypeError(f"degrees must be a number, got {type(degrees).__name__}")
        if not math.isfinite(degrees):
            raise ValueError(f"degrees={degrees} must be finite")
        return self._to_tensor(self._read(self._find(obj, float(degrees))))

    def images(self, obj: int, degrees_list: Sequence[float] | torch.Tensor) -> torch.Tensor:
        """Returns the views of object ``obj`` at each angle of ``degrees_list`` ``(T,)``.

        Returns:
            A tensor ``(T, C, H, W)`` of ``self.dtype``.
        """
        angles = as_angle_tensor(degrees_list, "degrees_list").tolist()
        return torch.stack([self._to_tensor(self._read(self._find(obj, a))) for a in angles])

    def load_all(
        self, objects: Iterable[int] | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Loads every pose, sorted by angle, of ``objects`` in their order (default: all, sorted).

        Returns:
            ``images`` ``(M, C, H, W)``, ``labels`` ``(M,)`` int64 object ids and ``poses``
            ``(M,)`` float64 degrees.
        """
        objs = self.objects if objects is None else list(objects)
        if not objs:
            raise ValueError("objects must name at least one object, got an empty collection")
        labels, poses, imgs = [], [], []
        for obj in objs:
            for deg, path in sorted(self._views(obj).items()):
                labels.append(obj)
                poses.append(deg)
                imgs.append(self._to_tensor(self._read(path)))
        labels_t, poses_t = torch.tensor(labels, dtype=torch.int64), torch.tensor(poses, dtype=torch.float64)
        return torch.stack(imgs), labels_t, poses_t

    def _views(self, obj: int) -> dict[float, Path]:
        try:
            key = operator.index(obj)
        except TypeError:
            raise TypeError(f"obj must be an int object id, got {type(obj).__name__}") from None
        if key not in self._files:
            raise ValueError(f"obj={obj} is not in {self.root} (objects: {self.objects})")
        return self._files[key]

    def _find(self, obj: int, degrees: float) -> Path:
        views = self._views(obj)
        wrapped = degrees % 360.0
        for deg, path in views.items():
            diff = abs(wrapped - deg)
            if min(diff, 360.0 - diff) <= _ANGLE_TOL:  # circular, so 359.9999999 finds 0
                return path
        have = [f"{v:g}" for v in sorted(views)]
        if len(have) > 8:
            have = [*have[:3], "...", *have[-2:]]
        raise ValueError(
            f"obj={obj} has no image at degrees={degrees!r} ({wrapped!r} mod 360); "
            f"available: [{', '.join(have)}] ({len(views)} poses)"
        )

    def _read(self, path: Path) -> np.ndarray:
        cached = self._cache.get(path)
        if cached is None:
            cached = read_image(path)
            if cached.shape != self.image_shape:
                raise ValueError(
                    f"image {path} must have shape (C, H, W)={self.image_shape} like the first image, "
                    f"got {cached.shape}"
                )
            self._cache[path] = cached
        return cached

    def _to_tensor(self, arr: np.ndarray) -> torch.Tensor:
        # Cached arrays keep their file dtype (uint8 is 4x smaller than float32); converting
        # here also hands out a fresh tensor, so callers cannot alter the cache in place.
        # The pixels are those of ``eigview predict``, which converts with the same function.
        work = np.float64 if self.dtype == torch.float64 else np.float32
        return torch.from_numpy(to_unit_float(arr, work)).to(self.device, self.dtype)
