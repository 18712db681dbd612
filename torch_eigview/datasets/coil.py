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
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import torch

from torch_eigview.check import as_angle_tensor, check_choice, check_limit, check_number
from torch_eigview.datasets.background import BackgroundModel, set_background
from torch_eigview.datasets.coil_names import (
    ANGLE_TOL,
    INDEX_STEP,
    POSE_UNITS,
    PoseStepWarning,
    check_pose_step,
    pose_files,
    resolve_pose_unit,
    scan_files,
    warn_whole_circle,
)
from torch_eigview.io.images import read_image, to_unit_float

__all__ = [
    "DATA_ENV",
    "CoilFolder",
    "PoseStepWarning",
    "find_coil_root",
    "get_data_home",
    "parse_object_spec",
]

#: The environment variable naming the folder that holds the data sets (``coil-20-proc/``, …).
DATA_ENV = "TORCH_EIGVIEW_DATA"

# re.ASCII: ``\d`` alone would also accept non-ASCII digits such as "١-3".
_SPEC_RE = re.compile(r"\s*([0-9]+)\s*(?:-\s*([0-9]+)\s*)?", re.ASCII)


def get_data_home(data_home: str | os.PathLike[str] | None = None) -> Path:
    """The folder that holds the data sets, as scikit-learn's ``get_data_home`` finds it:
    ``data_home`` when given, else the ``TORCH_EIGVIEW_DATA`` environment variable, else
    ``~/torch_eigview_data``.

    An empty ``TORCH_EIGVIEW_DATA`` counts as unset. The folder need not exist; nothing is
    downloaded into it: put the data sets there yourself (COIL-20's ``coil-20-proc/``).

    Example:
        >>> str(get_data_home("/data"))
        '/data'
    """
    return _data_home(data_home)[0]


def _data_home(data_home: str | os.PathLike[str] | None) -> tuple[Path, str]:
    """:func:`get_data_home` and where it came from, in words: the one reading of the
    environment in the library."""
    if data_home is not None:
        return Path(data_home).expanduser(), "under the data_home given"
    env = os.environ.get(DATA_ENV, "")
    if env:
        return Path(env).expanduser(), f"from {DATA_ENV}={env}"
    return Path("~/torch_eigview_data").expanduser(), f"the default data home, {DATA_ENV} being unset"


def find_coil_root(
    root: str | os.PathLike[str] | None = None,
    name: str = "coil-20-proc",
    data_home: str | os.PathLike[str] | None = None,
) -> Path:
    """The folder of COIL images to read: ``root`` when given, else ``get_data_home(data_home) / name``.

    Args:
        root: The COIL folder itself (``obj{O}__{P}.png`` files), or None for the default.
        name: The folder under the data home when ``root`` is None (``"coil-20-proc"``
            for the processed COIL-20, e.g. ``"coil-100"`` for COIL-100).
        data_home: the data home (:func:`get_data_home`).

    Returns:
        The folder; it exists (whether it holds COIL files, :class:`CoilFolder` checks).

    Raises:
        TypeError: ``root`` is not a path or ``name`` not a str.
        ValueError: The folder does not exist; the message says which folder was looked
            for, why there, and the ways to point at the images.
    """
    if root is not None and not isinstance(root, (str, os.PathLike)):
        raise TypeError(f"root must be a str, a path or None, got {type(root).__name__}")
    if not isinstance(name, str):
        raise TypeError(f"name must be a str such as 'coil-20-proc', got {type(name).__name__}")
    home, source = _data_home(data_home)
    path = Path(root) if root is not None else home / name
    if path.is_dir():
        return path
    if root is not None:
        source = "given as the folder itself"
    raise ValueError(
        f"COIL images not found: {str(path)!r} ({source}) must be an existing directory of "
        f"obj{{O}}__{{P}}.png images. Put the {name}/ folder in {home}, or set {DATA_ENV} to the "
        f"folder that holds {name}/, or pass the folder itself (eigview coil --folder DIR)."
    )


# Object ids one selection may name (COIL-100 has 100).
OBJECT_LIMIT = "max_objects"


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
        check_limit(len(ids) + hi - lo + 1, f"spec={spec!r}", "object ids", OBJECT_LIMIT)
        ids.update(range(lo, hi + 1))
    return sorted(ids)


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
        background: a :class:`~torch_eigview.datasets.background.BackgroundModel` whose
            masks (estimated from each image's border, or from its colour) set every view's
            background to the model's ``fill`` (0: the black background the COIL pipeline
            assumes), or None (default) for the pixels as read. Each file's mask is
            estimated once and cached.

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
        background: BackgroundModel | None = None,
    ) -> None:
        if not isinstance(root, (str, os.PathLike)):
            raise TypeError(f"root must be a str or a path, got {type(root).__name__}")
        if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
            raise TypeError(f"dtype must be a floating torch.dtype, got {dtype!r}")
        pose_unit = check_choice(pose_unit, "pose_unit", POSE_UNITS)
        if background is not None and not isinstance(background, BackgroundModel):
            raise TypeError(f"background must be a BackgroundModel or None, got {type(background).__name__}")
        #: The background rule applied to every view read, or None.
        self.background = background
        self._masks: dict[Path, torch.Tensor] = {}
        given_step = check_pose_step(pose_step, pose_unit)
        self.root = Path(root)
        if not self.root.is_dir():
            raise ValueError(f"root={str(self.root)!r} must be an existing directory")
        found = scan_files(self.root)
        if not found:
            raise ValueError(f"root={str(self.root)!r} holds no COIL files (obj{{O}}__{{P}}.png)")
        self.pose_unit = resolve_pose_unit(found) if pose_unit == "auto" else pose_unit
        pose_unit = self.pose_unit
        self.dtype = dtype
        self.device = torch.device(device)
        if pose_unit == "degrees" and given_step is not None:
            raise ValueError(
                f"pose_step={pose_step!r} needs pose files named by index, but the folder's poses "
                "are degrees (some P >= 72; pose_unit 'auto' resolved to 'degrees')"
            )
        #: Degrees between consecutive file poses P.
        self.pose_step = (INDEX_STEP if given_step is None else given_step) if pose_unit == "index" else 1.0
        self._files = pose_files(found, pose_unit, self.pose_step)
        if pose_unit == "index" and given_step is None:
            warn_whole_circle(self.root, self._files)
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
            f"pose_unit={self.pose_unit!r}, pose_step={self.pose_step:g}, image_shape={self.image_shape}"
            + ("" if self.background is None else f", background={self.background!r}")
            + ")"
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
        return self._load(self._find(obj, float(degrees)))

    def images(self, obj: int, degrees_list: Sequence[float] | torch.Tensor) -> torch.Tensor:
        """Returns the views of object ``obj`` at each angle of ``degrees_list`` ``(T,)``.

        Returns:
            A tensor ``(T, C, H, W)`` of ``self.dtype``.
        """
        angles = as_angle_tensor(degrees_list, "degrees_list").tolist()
        return torch.stack([self._load(self._find(obj, a)) for a in angles])

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
                imgs.append(self._load(path))
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
            if min(diff, 360.0 - diff) <= ANGLE_TOL:  # circular, so 359.9999999 finds 0
                return path
        have = [f"{v:g}" for v in sorted(views)]
        if len(have) > 8:
            have = [*have[:3], "...", *have[-2:]]
        raise ValueError(
            f"obj={obj} has no image at degrees={degrees!r} ({wrapped!r} mod 360); "
            f"available: [{', '.join(have)}] ({len(views)} poses)"
        )

    def _load(self, path: Path) -> torch.Tensor:
        """The view in ``path`` as a new (C, H, W) tensor, its background set where
        :attr:`background` says (the file's mask estimated once, then cached)."""
        view = self._to_tensor(self._read(path))
        if self.background is None or self.background.fill is None:
            return view
        mask = self._masks.get(path)
        if mask is None:
            try:
                mask = self.background.masks(view[None])[0]
            except ValueError as exc:  # e.g. the colour leaves no object: name the file
                raise ValueError(f"{path}: {exc}") from None
            self._masks[path] = mask
        return set_background(view[None], mask[None], self.background.fill)[0]

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
