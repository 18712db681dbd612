"""Versioned, checksummed save and load of a fitted recognizer, or of a module's state_dict.

A file is a ``torch.save`` of plain tensors, numbers and strings only, so it loads with
``torch.load(weights_only=True)``: loading never runs code from the file. It records the
SHA-256 of its tensors (dtype, shape and bytes) and of every other entry, metadata included,
and loading recomputes it: a bit flipped anywhere, on disk or in transit, is refused with
an error naming the file, never loaded as a model that answers wrongly. Files are written
atomically (:func:`torch_eigview.files.atomic_output`): a failed or killed save leaves the
previous file as it was, and says so.

The checksum catches corruption, not a file edited with its checksum recomputed, nor one
written by a buggy writer. Loading therefore also checks the content against itself
(:func:`check_recognizer_payload`, and for a state_dict the projections and recognizers it
holds): shapes that agree (``image_shape`` multiplies to N), finite values, orthonormal
components, one distinct name per label. An error names the file, the entry, what was
expected and what the file holds.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Mapping
from typing import Any, NoReturn, cast

import torch

from torch_eigview.files import atomic_output, check_output_path, write_error
from torch_eigview.nn.kernel_projection import KERNELS, KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "ORTHONORMAL_TOLERANCE",
    "STATE_DICT_FORMAT",
    "check_recognizer_payload",
    "check_state_dict",
    "load_recognizer",
    "load_state_dict",
    "payload_digest",
    "save_recognizer",
    "save_state_dict",
]

FORMAT = "torch_eigview.recognizer"
# Version 2 added the checksum; version 3 the "projection" entry and kernel projections.
# Version 2 files (linear eigenspaces) still load; version 1 files (no checksum) are refused.
FORMAT_VERSION = 3
_READ_VERSIONS = (2, 3)
STATE_DICT_FORMAT = "torch_eigview.state_dict"
STATE_DICT_VERSION = 1
_DIGEST_KEY = "sha256"
ORTHONORMAL_TOLERANCE = 1e-3
"""The largest ``|C Cᵀ − I|`` (any entry, computed in float64) a file's (k, N) components may
show: far above float32 rounding of a fitted eigenspace, far below any rescaled or mixed
component (components scaled by 2 give 3)."""


def _feed(h: Any, value: object) -> None:
    """Feeds ``value`` to the hash in an unambiguous encoding: every item says its kind and size."""
    if isinstance(value, torch.Tensor):
        t = value.detach().cpu().contiguous().reshape(-1)
        h.update(f"tensor {t.dtype} {list(value.shape)};".encode())
        h.update(t.view(torch.uint8).numpy())  # the raw bytes, no copy
    elif isinstance(value, Mapping):
        h.update(f"dict {len(value)};".encode())
        for key in sorted(value, key=str):
            _feed(h, str(key))
            _feed(h, value[key])
    elif isinstance(value, (list, tuple)):
        h.update(f"list {len(value)};".encode())
        for item in value:
            _feed(h, item)
    else:  # str, int, float, bool, None: JSON spells each exactly and distinctly
        h.update(f"value {json.dumps(value)};".encode())


def payload_digest(payload: Mapping[str, object]) -> str:
    """SHA-256 (hex) of a file's entries, all but the digest itself.

    Example:
        >>> payload_digest({"a": torch.zeros(2)}) == payload_digest({"a": torch.zeros(2)})
        True
        >>> payload_digest({"a": torch.zeros(2)}) == payload_digest({"a": torch.zeros(2, 1)})
        False
    """
    h = hashlib.sha256()
    _feed(h, {k: v for k, v in payload.items() if k != _DIGEST_KEY})
    return h.hexdigest()


def _write(path: str | os.PathLike[str], payload: dict[str, Any]) -> None:
    """Checks ``path``, adds the digest and writes ``payload`` atomically."""
    text = check_output_path(path, "path")
    payload[_DIGEST_KEY] = payload_digest(payload)
    try:
        with atomic_output(text) as tmp, open(tmp, "wb") as fh:
            # A Python file: a failed write raises OSError with its errno (disk full, file-size
            # limit), where torch's own file writer reports only "iostream error".
            torch.save(payload, fh)
    except KeyboardInterrupt:  # still an interrupt (it must stop the program), but saying so
        raise KeyboardInterrupt(
            f"could not write {text!r} (interrupted); any previous file is unchanged"
        ) from None
    except RuntimeError as exc:
        # torch's zip writer turns an OSError (or a Ctrl-C) inside its writes into
        # "[enforce fail at inline_container.cc] unexpected pos …", the cause as its context.
        # atomic_output has already removed the temporary file.
        if isinstance(exc.__context__, KeyboardInterrupt):
            raise KeyboardInterrupt(
                f"could not write {text!r} (interrupted); any previous file is unchanged"
            ) from None
        raise write_error(text, exc) from exc


def _read(path: str | os.PathLike[str], fmt: str, versions: tuple[int, ...], what: str) -> dict[str, Any]:
    """Loads (weights only) and verifies a file of format ``fmt`` and one of ``versions``;
    ``what`` names it in errors."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ValueError(f"model file {path!r} does not exist")
    if not os.path.isfile(path):
        raise ValueError(f"model file {path!r} is not a file")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # a truncated or damaged zip, or an arbitrary file: report which
        raise ValueError(
            f"model file {path!r} could not be read as a torch_eigview model (damaged, truncated or "
            f"another kind of file): {exc}"
        ) from exc
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        raise ValueError(f"model file {path!r} is not a torch_eigview {what} (format {fmt!r} expected)")
    if payload.get("version") not in versions:
        older = " (version 1 had no checksum: save the model again)" if payload.get("version") == 1 else ""
        said = str(versions[-1]) + (
            f" (and {', '.join(map(str, versions[:-1]))})" if len(versions) > 1 else ""
        )
        raise ValueError(
            f"model file {path!r} has format version {payload.get('version')!r}; this torch_eigview "
            f"reads version {said}{older}"
        )
    recorded = payload.get(_DIGEST_KEY)
    try:
        actual = payload_digest(payload)
    except (TypeError, ValueError, RuntimeError) as exc:  # e.g. a key flipped into a non-string
        raise ValueError(f"{path}: checksum mismatch: the file is corrupted ({exc})") from exc
    if recorded != actual:
        said = f"{recorded[:16]}…" if isinstance(recorded, str) else "no checksum"
        raise ValueError(
            f"{path}: checksum mismatch: the file is corrupted (the SHA-256 of its contents is "
            f"{actual[:16]}…, torch_eigview recorded {said}); restore it from a copy or write it again"
        )
    return payload


def _path_first(function: str, order: str, first: object) -> None:
    """TypeError when a save function is called in the old (path, object) order."""
    if isinstance(first, (str, os.PathLike)):
        raise TypeError(
            f"{function} takes ({order}), the object first as torch.save does; got the path "
            f"{os.fspath(first)!r} first: swap the arguments"
        )


def _projection_entries(proj: object) -> dict[str, Any]:
    """The entries that describe a recognizer's projection (linear or kernel)."""
    if isinstance(proj, EigenProjection):
        return {
            "projection": "linear",
            "mean": proj.mean.detach().cpu(),
            "components": proj.components.detach().cpu(),
            "eigenvalues": proj.eigenvalues.detach().cpu(),
        }
    if isinstance(proj, KernelProjection):
        return {
            "projection": "kernel",
            "vectors": proj.vectors.detach().cpu(),
            "coefficients": proj.coefficients.detach().cpu(),
            "kernel_mean": proj.kernel_mean.detach().cpu(),
            "eigenvalues": proj.eigenvalues.detach().cpu(),
            "kernel": proj.kernel,
            "gamma": float(proj.gamma),
            "degree": int(proj.degree),
            "coef0": float(proj.coef0),
        }
    raise TypeError(
        f"recognizer.projection must be an EigenProjection or a KernelProjection, got {type(proj).__name__}"
    )


def save_recognizer(
    recognizer: NearestNeighborRecognizer,
    path: str | os.PathLike[str],
    metadata: dict[str, Any] | None = None,
) -> None:
    """Writes the recognizer (projection, gallery, labels, poses) and JSON-like ``metadata``.

    The projection is an :class:`EigenProjection` (mean, components, eigenvalues) or a
    :class:`KernelProjection` (kernel and its parameters, stored views, coefficients, mean
    kernel row). The file replaces ``path`` atomically, with the SHA-256 of its contents.
    Arguments come as for ``torch.save``: the object, then the path.

    Raises:
        TypeError: ``recognizer`` is not a recognizer over an :class:`EigenProjection` or a
            :class:`KernelProjection`, ``metadata`` holds non-JSON values, or the path is
            given first (the order before ``(recognizer, path)``).
        ValueError: ``path`` cannot be written (a directory, a special file, a missing or
            read-only folder), or the recognizer's content would not load
            (:func:`check_recognizer_payload`: e.g. components that are not orthonormal).
        OSError: the write failed (disk full, file-size limit); ``path`` is unchanged.
    """
    _path_first("save_recognizer", "recognizer, path, metadata=None", recognizer)
    check_output_path(path, "path")
    if not isinstance(recognizer, NearestNeighborRecognizer):
        raise TypeError(f"recognizer must be a NearestNeighborRecognizer, got {type(recognizer).__name__}")
    meta = dict(metadata or {})
    try:
        json.dumps(meta, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"metadata must hold JSON values only (str, int, float, bool, None, lists, dicts): {exc}"
        ) from exc
    proj = recognizer.projection
    payload = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        **_projection_entries(proj),
        "image_shape": list(proj.image_shape) if proj.image_shape is not None else None,
        "unit_norm": proj.unit_norm,
        "codes": recognizer.codes.detach().cpu(),
        "labels": recognizer.labels.detach().cpu(),
        "poses": recognizer.poses.detach().cpu(),
        "label_names": recognizer.label_names,
        "reject_thresholds": recognizer.reject_thresholds.detach().cpu(),
        "metadata": meta,
    }
    check_recognizer_payload(payload, "the recognizer to save")  # never write what would not load
    _write(path, payload)


def load_recognizer(path: str | os.PathLike[str]) -> tuple[NearestNeighborRecognizer, dict[str, Any]]:
    """Reads a file written by :func:`save_recognizer`, after verifying its checksum and content.

    Returns:
        ``(recognizer, metadata)``; the recognizer's projection is an :class:`EigenProjection`
        or a :class:`KernelProjection`, as saved.

    Raises:
        ValueError: the file is missing, truncated, corrupted (checksum mismatch), not one
            of ours, of another version, or its content contradicts itself
            (:func:`check_recognizer_payload`); the message names the file and the entry.
    """
    payload = _read(path, FORMAT, _READ_VERSIONS, "recognizer")
    source = f"model file {os.fspath(path)!r}"
    if payload["version"] == 2:  # before kernel projections: always linear
        payload.setdefault("projection", "linear")
    check_recognizer_payload(payload, source)
    try:
        shape = payload["image_shape"]
        image_shape = tuple(shape) if shape is not None else None
        eigenvalues = payload["eigenvalues"] if payload["eigenvalues"].numel() else None
        projection: EigenProjection | KernelProjection
        if payload["projection"] == "kernel":
            projection = KernelProjection.from_tensors(
                payload["vectors"],
                payload["coefficients"],
                payload["kernel_mean"],
                kernel=payload["kernel"],
                gamma=payload["gamma"],
                degree=payload["degree"],
                coef0=payload["coef0"],
                eigenvalues=eigenvalues,
                image_shape=image_shape,
                unit_norm=bool(payload["unit_norm"]),
            )
        else:
            projection = EigenProjection.from_tensors(
                payload["mean"],
                payload["components"],
                eigenvalues,
                image_shape,
                unit_norm=bool(payload["unit_norm"]),
            )
        # Files written before rejection existed have no thresholds: (0,) means none too.
        thresholds = payload.get("reject_thresholds")
        recognizer = NearestNeighborRecognizer(
            projection,
            payload["codes"],
            payload["labels"],
            payload["poses"],
            payload["label_names"],
            thresholds if thresholds is not None and thresholds.numel() else None,
        )
        return recognizer, dict(payload["metadata"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(f"{source} is a damaged or incomplete torch_eigview model: {exc}") from exc


class _Entries:
    """The entries of a file (or a state_dict) under check; errors name the source and the entry."""

    def __init__(
        self, entries: Mapping[str, object], source: str, prefix: str = "", shown: str | None = None
    ) -> None:
        # Keys are looked up as prefix + key and named as shown + key in errors.
        self.entries, self.source, self.prefix = entries, source, prefix
        self.shown = prefix if shown is None else shown

    def fail(self, key: str, expected: str, got: object) -> NoReturn:
        raise ValueError(f"{self.source}: entry {self.shown + key!r} must be {expected}, got {got}")

    def get(self, key: str) -> object:
        if self.prefix + key not in self.entries:
            self.fail(key, "present", "no such entry")
        return self.entries[self.prefix + key]

    def tensor(
        self,
        key: str,
        layout: str,
        dims: tuple[int | None, ...],
        *,
        floating: bool = True,
        finite: bool = True,
    ) -> torch.Tensor:
        """The tensor ``key`` of shape ``dims`` (None: any size >= 1), named ``layout`` ("(G, k)")."""
        value = self.get(key)
        names = layout.strip("(,)").split(", ")
        known = ", ".join(n if d is None else str(d) for n, d in zip(names, dims, strict=True))
        want = f"shape {layout}" + (
            f" = ({known}{',' if len(dims) == 1 else ''})" if known != ", ".join(names) else ""
        )
        kind = "a floating" if floating else "an integer"
        if not isinstance(value, torch.Tensor):
            self.fail(key, f"{kind} tensor of {want}", type(value).__name__)
        if floating != value.is_floating_point() or value.is_complex() or value.dtype == torch.bool:
            self.fail(key, f"{kind} tensor of {want}", f"dtype {value.dtype}")
        if value.ndim != len(dims) or any(
            s < 1 if d is None else s != d for s, d in zip(value.shape, dims, strict=False)
        ):
            self.fail(key, f"a tensor of {want}", f"shape {tuple(value.shape)}")
        if finite and floating and not bool(torch.isfinite(value).all()):
            self.fail(key, "finite", f"{int((~torch.isfinite(value)).sum())} NaN or infinite value(s)")
        return value

    def eigenvalues(self, k: int, reference: torch.Tensor, name: str) -> None:
        value = self.get("eigenvalues")
        if isinstance(value, torch.Tensor) and tuple(value.shape) == (0,):
            dims: tuple[int, ...] = (0,)
        else:
            dims = (k,)
        values = self.tensor("eigenvalues", "(k,)", dims)
        if values.dtype != reference.dtype:
            self.fail("eigenvalues", f"of dtype {reference.dtype} like {name}", f"dtype {values.dtype}")
        if bool((values < 0).any()):
            self.fail("eigenvalues", ">= 0 (variances)", f"{values.min().item():g}")

    def number(self, key: str, expected: str, ok: Any) -> Any:
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not ok(value):
            self.fail(key, expected, repr(value))
        return value


def _check_linear(e: _Entries, tolerance: float) -> int:
    """Checks mean, components and eigenvalues; returns k."""
    components = e.tensor("components", "(k, N)", (None, None))
    k, n = components.shape
    if k > n:
        e.fail("components", f"at most N={n} rows (k <= N)", f"shape {tuple(components.shape)}")
    mean = e.tensor("mean", "(N,)", (n,))
    if mean.dtype != components.dtype:
        e.fail("mean", f"of dtype {components.dtype} like components", f"dtype {mean.dtype}")
    e.eigenvalues(k, components, "components")
    c = components.detach().to("cpu", torch.float64)
    error = float((c @ c.T - torch.eye(k, dtype=torch.float64)).abs().max())
    if error > tolerance:
        e.fail("components", f"orthonormal rows (|C Cᵀ − I| <= {tolerance:g})", f"|C Cᵀ − I| = {error:.3g}")
    return k


def _check_kernel_tensors(e: _Entries) -> tuple[int, int]:
    """Checks vectors, coefficients, kernel_mean and eigenvalues; returns (k, N)."""
    vectors = e.tensor("vectors", "(T, N)", (None, None))
    t, n = vectors.shape
    coefficients = e.tensor("coefficients", "(T, k)", (t, None))
    kernel_mean = e.tensor("kernel_mean", "(T,)", (t,))
    for value, key in ((coefficients, "coefficients"), (kernel_mean, "kernel_mean")):
        if value.dtype != vectors.dtype:
            e.fail(key, f"of dtype {vectors.dtype} like vectors", f"dtype {value.dtype}")
    e.eigenvalues(coefficients.shape[1], vectors, "vectors")
    return coefficients.shape[1], n


def _check_kernel_params(e: _Entries) -> None:
    kernel = e.get("kernel")
    if kernel not in KERNELS:
        e.fail("kernel", f"one of {KERNELS}", repr(kernel))
    e.number("gamma", "a finite number > 0", lambda v: math.isfinite(v) and v > 0)
    e.number("degree", "an int >= 1", lambda v: isinstance(v, int) and v >= 1)
    e.number("coef0", "a finite number", math.isfinite)


def _check_image_shape(e: _Entries, key: str, shape: object, n: int, required: bool = False) -> None:
    if shape is None and not required:
        return
    if not (
        isinstance(shape, (list, tuple))
        and len(shape) == 3
        and all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in shape)
    ):
        e.fail(key, "[C, H, W] of 3 ints >= 1" + ("" if required else " or None"), repr(shape))
    if math.prod(shape) != n:
        e.fail(
            key,
            f"[C, H, W] with C*H*W = N = {n}, the length of one view",
            f"{list(shape)} ({math.prod(shape)})",
        )


def check_recognizer_payload(
    payload: Mapping[str, object], source: str, *, tolerance: float = ORTHONORMAL_TOLERANCE
) -> None:
    """Checks a recognizer file's entries against each other, independently of its checksum.

    Shapes: a linear projection's ``mean`` (N,), ``components`` (k, N) orthonormal (every
    entry of ``C Cᵀ − I`` within ``tolerance``), ``eigenvalues`` (k,) or (0,); a kernel
    projection's ``vectors`` (T, N), ``coefficients`` (T, k), ``kernel_mean`` (T,), a known
    ``kernel`` with a finite ``gamma`` > 0, an int ``degree`` >= 1 and a finite ``coef0``;
    ``image_shape`` None or [C, H, W] with C*H*W = N; ``codes`` (G, k), ``labels`` (G,)
    integers, ``poses`` (G,); every float finite; ``label_names`` None or one distinct
    string per distinct label; ``reject_thresholds`` (0,) or (2,); ``unit_norm`` a bool;
    ``metadata`` a dict.

    Args:
        payload: the file's entries (as ``torch.load`` returns them).
        source: what the entries come from, first in every message (``"model file 'm.pt'"``).
        tolerance: see :data:`ORTHONORMAL_TOLERANCE`.

    Raises:
        ValueError: "SOURCE: entry 'NAME' must be EXPECTED, got WHAT".
    """
    e = _Entries(payload, source)
    kind = e.get("projection")
    if kind == "kernel":
        k, n = _check_kernel_tensors(e)
        _check_kernel_params(e)
    elif kind == "linear":
        k = _check_linear(e, tolerance)
        n = cast(torch.Tensor, payload["components"]).shape[1]
    else:
        e.fail("projection", "'linear' or 'kernel'", repr(kind))
    _check_image_shape(e, "image_shape", e.get("image_shape"), n)
    if not isinstance(e.get("unit_norm"), bool):
        e.fail("unit_norm", "a bool", repr(payload["unit_norm"]))
    codes = e.tensor("codes", "(G, k)", (None, k))
    g = codes.shape[0]
    labels = e.tensor("labels", "(G,)", (g,), floating=False)
    e.tensor("poses", "(G,)", (g,))
    _check_label_names(e, labels)
    if "reject_thresholds" in payload:  # absent from files written before rejection
        thresholds = e.get("reject_thresholds")
        n_values = thresholds.numel() if isinstance(thresholds, torch.Tensor) else 2
        values = e.tensor(
            "reject_thresholds", "(2,)", (n_values,) if n_values in (0, 2) else (2,), finite=False
        )
        if bool((values.isnan() | (values <= 0)).any()):
            e.fail("reject_thresholds", "(t_dffs, t_difs), each > 0 or inf", values.tolist())
    if not isinstance(e.get("metadata"), dict):
        e.fail("metadata", "a dict", type(payload["metadata"]).__name__)


def _check_label_names(e: _Entries, labels: torch.Tensor) -> None:
    names = e.get("label_names")
    if names is None:
        return
    distinct = labels.unique().tolist()
    if not isinstance(names, list) or not all(isinstance(v, str) for v in names):
        e.fail("label_names", "None or a list of str", repr(names)[:200])
    if len(names) != len(distinct):
        e.fail(
            "label_names",
            f"one name per distinct label ({len(distinct)} labels)",
            f"{len(names)} names",
        )
    repeated = sorted({v for v in names if names.count(v) > 1})
    if repeated:
        e.fail("label_names", "distinct names, one per label", f"{repeated[:5]!r} more than once")


def save_state_dict(state_dict: Mapping[str, object], path: str | os.PathLike[str]) -> None:
    """Writes a module's ``state_dict`` atomically, with its SHA-256.

    Values are tensors, or the plain values of a module's extra state (``image_shape``,
    ``unit_norm``). Arguments come as for ``torch.save``: the object, then the path.

    Read it back with :func:`load_state_dict`, then ``module.load_state_dict(...)``.

    Raises:
        TypeError: ``state_dict`` is not a mapping of str to tensors or plain values, or
            the path is given first (the order before ``(state_dict, path)``).
        ValueError: ``path`` cannot be written, or a projection or recognizer in the
            state_dict would not load (:func:`check_state_dict`).
        OSError: the write failed; ``path`` is unchanged.
    """
    _path_first("save_state_dict", "state_dict, path", state_dict)
    check_output_path(path, "path")
    if not isinstance(state_dict, Mapping):
        raise TypeError(f"state_dict must be a mapping of str to tensors, got {type(state_dict).__name__}")
    entries: dict[str, Any] = {}
    for key, value in state_dict.items():
        if not isinstance(key, str):
            raise TypeError(f"state_dict keys must be str, got {key!r}")
        if isinstance(value, torch.Tensor):
            entries[key] = value.detach().cpu()
            continue
        try:  # a module's extra state: plain values that weights_only loading accepts
            json.dumps(value, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"state_dict[{key!r}] must be a tensor or JSON-like values: {exc}") from exc
        entries[key] = value
    check_state_dict(entries, "the state_dict to save")  # never write what would not load
    _write(path, {"format": STATE_DICT_FORMAT, "version": STATE_DICT_VERSION, "state_dict": entries})


def load_state_dict(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Reads a file written by :func:`save_state_dict`, after verifying its checksum and
    the content of the projections and recognizers it holds (:func:`check_state_dict`).

    Raises:
        ValueError: the file is missing, truncated, corrupted, not a state_dict file, or a
            projection or recognizer in it contradicts itself.
    """
    payload = _read(path, STATE_DICT_FORMAT, (STATE_DICT_VERSION,), "state_dict")
    state = payload.get("state_dict")
    if not isinstance(state, dict):
        raise ValueError(f"model file {os.fspath(path)!r} is a damaged torch_eigview state_dict file")
    check_state_dict(state, f"model file {os.fspath(path)!r}")
    return state


_EXTRA = "_extra_state"


def check_state_dict(
    state: Mapping[str, object], source: str, *, tolerance: float = ORTHONORMAL_TOLERANCE
) -> None:
    """Checks the frozen projections in a ``state_dict``, and the recognizers over them.

    A projection is found by its extra state (``PREFIX_extra_state``, a dict with
    ``image_shape``) next to ``PREFIXmean`` and ``PREFIXcomponents`` (linear: checked as in
    :func:`check_recognizer_payload`, orthonormal) or ``PREFIXvectors``,
    ``PREFIXcoefficients`` and ``PREFIXkernel_mean`` (kernel, with its parameters); its
    ``image_shape`` must multiply to N. A recognizer over it (``codes``, ``labels``,
    ``poses`` beside ``projection.``) must have (G, k), (G,) and (G,) finite entries. Other
    entries (a head's weights) are the module's own business.

    Raises:
        ValueError: "SOURCE: entry 'NAME' must be EXPECTED, got WHAT".
    """
    for key, extra in state.items():
        if not key.endswith(_EXTRA) or not isinstance(extra, dict) or "image_shape" not in extra:
            continue
        prefix = key[: -len(_EXTRA)]
        e = _Entries(state, source, prefix)
        if prefix + "components" in state and prefix + "mean" in state:
            k = _check_linear(e, tolerance)
            n = cast(torch.Tensor, state[prefix + "components"]).shape[1]
        elif prefix + "coefficients" in state and prefix + "vectors" in state:
            k, n = _check_kernel_tensors(e)
            _check_kernel_params(_Entries(extra, source, shown=key + "."))
        else:
            continue
        _check_image_shape(e, _EXTRA + ".image_shape", extra["image_shape"], n)
        owner = prefix[: -len("projection.")] if prefix.endswith("projection.") else None
        if owner is not None and owner + "codes" in state:
            g = _Entries(state, source, owner)
            codes = g.tensor("codes", "(G, k)", (None, k))
            g.tensor("labels", "(G,)", (codes.shape[0],), floating=False)
            g.tensor("poses", "(G,)", (codes.shape[0],))
