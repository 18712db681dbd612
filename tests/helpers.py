"""Test helpers: seeded random data and the one ``check_module`` used for every nn.Module."""

from __future__ import annotations

import copy
import dataclasses
import io
from collections.abc import Sequence
from typing import Any

import pytest
import torch
import torch.nn.functional as F


def rand(
    *shape: int,
    seed: int = 0,
    dtype: torch.dtype = torch.float64,
    device: torch.device | str = "cpu",
) -> torch.Tensor:
    """Uniform [0, 1) data made on the CPU with a fixed seed, then moved: the same on every device."""
    gen = torch.Generator().manual_seed(seed)
    return torch.rand(*shape, generator=gen, dtype=torch.float64).to(device=device, dtype=dtype)


def _map_tensors(obj: Any, fn: Any) -> Any:
    """Applies ``fn`` to every tensor in ``obj`` (tensors, tuples, lists, dicts, dataclasses)."""
    if isinstance(obj, torch.Tensor):
        return fn(obj)
    if isinstance(obj, (tuple, list)):
        return type(obj)(_map_tensors(v, fn) for v in obj)
    if isinstance(obj, dict):
        return {k: _map_tensors(v, fn) for k, v in obj.items()}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        changes = {f.name: _map_tensors(getattr(obj, f.name), fn) for f in dataclasses.fields(obj)}
        return dataclasses.replace(obj, **changes)
    return obj


def _tensors(obj: Any) -> list[torch.Tensor]:
    found: list[torch.Tensor] = []
    _map_tensors(obj, lambda t: found.append(t) or t)
    return found


def _assert_same(actual: Any, expected: Any, what: str, **tol: float) -> None:
    got, want = _tensors(actual), _tensors(expected)
    assert len(got) == len(want), f"{what}: {len(got)} output tensors, expected {len(want)}"
    for g, w in zip(got, want, strict=True):
        torch.testing.assert_close(g, w, equal_nan=True, msg=lambda m: f"{what}: {m}", **tol)


def check_module(
    module: torch.nn.Module,
    inputs: tuple[Any, ...],
    kwargs: dict[str, Any] | None = None,
    *,
    batched_kwargs: Sequence[str] = (),
    empty_batch: bool = True,
    tol: dict[str, float] | None = None,
    check_compile: bool = False,
    check_export: bool = False,
) -> None:
    """Invariants every module of the package keeps.

    Checks that ``module(*inputs, **kwargs)``

    - leaves its input tensors unchanged (no in-place writes);
    - returns the dtype of ``inputs[0]`` in every floating output (integer outputs such as
      labels or indices keep their integer dtype) and the device of ``inputs[0]`` in all;
    - on the whole batch equals the per-sample calls concatenated along dim 0;
    - works on an empty batch (B = 0) when ``empty_batch``;
    - gives the same output after a ``state_dict`` round trip (saved, loaded with
      ``weights_only=True`` into a copy whose tensors were zeroed) and after pickling the
      whole module (``torch.save`` / ``torch.load(weights_only=False)``);
    - gives the same output through ``torch.compile(backend="eager")`` when ``check_compile``:
      TorchDynamo captures ``forward`` into graphs (breaking the graph where Python must
      see a value, such as a validation check) and runs them with the eager kernels, so
      anything Dynamo traces wrongly shows up as a difference;
    - gives the same output as one whole graph from ``torch.export.export`` when
      ``check_export`` (no graph breaks allowed: no ``.item()``, no branching on data), the
      property an ONNX export relies on.

    Args:
        module: the module under test, already on the inputs' device.
        inputs: positional arguments; ``inputs[0]`` is a (B, ...) tensor, B >= 1. Every tensor among
            them (also inside tuples or dataclasses such as ``Correspondence``; None passes
            through) is batched along dim 0.
        kwargs: keyword arguments; only those named in ``batched_kwargs`` are split along
            dim 0, the others (angles, options) are passed to every call unchanged.
        batched_kwargs: names of the keyword arguments that carry the batch dimension.
        empty_batch: also call the module with B = 0.
        tol: ``atol``/``rtol`` for the batched-vs-per-sample comparison; default
            ``torch.testing.assert_close``'s for the dtype. The round trips must be exact.
        check_compile: also compare ``torch.compile(module, backend="eager")`` with eager; the
            compiled call uses ``tol`` too, as Dynamo may reorder the arithmetic. Compiling
            takes seconds for the warps, so ``tests/nn/test_modules.py`` runs it once per
            module class rather than every caller on every parametrization.
        check_export: also compare the ``torch.export`` program with eager (within ``tol``);
            for modules whose arguments are all tensors.
    """
    kwargs = dict(kwargs or {})
    tol = dict(tol or {})
    first = inputs[0]
    n = first.shape[0]
    assert n > 0, "check_module needs a non-empty batch (it checks B = 0 itself)"
    unknown = set(batched_kwargs) - set(kwargs)
    assert not unknown, f"batched_kwargs {sorted(unknown)} are not in kwargs"

    def call(m: torch.nn.Module, index: slice | None = None) -> Any:
        if index is None:
            return m(*inputs, **kwargs)
        args = _map_tensors(inputs, lambda t: t[index])
        kw = {k: _map_tensors(v, lambda t: t[index]) if k in batched_kwargs else v for k, v in kwargs.items()}
        return m(*args, **kw)

    before = _map_tensors((inputs, kwargs), lambda t: t.detach().clone())
    out = call(module)
    _assert_same((inputs, kwargs), before, "inputs modified in place", atol=0.0, rtol=0.0)

    for t in _tensors(out):
        if t.is_floating_point():
            assert t.dtype == first.dtype, f"output dtype {t.dtype} != input dtype {first.dtype}"
        assert t.device == first.device, f"output device {t.device} != input device {first.device}"
        assert t.shape[0] == n, f"output batch {t.shape[0]} != input batch {n}"

    per_sample = [call(module, slice(i, i + 1)) for i in range(n)]
    parts = [_tensors(p) for p in per_sample]
    stacked = [torch.cat([p[j] for p in parts]) for j in range(len(parts[0]))]
    _assert_same(out, stacked, "batched != per-sample", **tol)

    if empty_batch:
        empty = call(module, slice(0, 0))
        for t in _tensors(empty):
            assert t.shape[0] == 0, f"empty batch gave an output of shape {tuple(t.shape)}"
        assert [t.shape[1:] for t in _tensors(empty)] == [t.shape[1:] for t in _tensors(out)]

    buffer = io.BytesIO()
    torch.save(module.state_dict(), buffer)
    buffer.seek(0)
    restored = copy.deepcopy(module)
    with torch.no_grad():
        for t in restored.state_dict().values():
            if isinstance(t, torch.Tensor):  # extra state (a module's dict of settings) stays
                t.zero_()
    restored.load_state_dict(torch.load(buffer, weights_only=True))
    _assert_same(call(restored), out, "state_dict round trip", atol=0.0, rtol=0.0)

    buffer = io.BytesIO()
    torch.save(module, buffer)
    buffer.seek(0)
    unpickled = torch.load(buffer, weights_only=False, map_location=first.device)
    assert type(unpickled) is type(module) and repr(unpickled) == repr(module)
    _assert_same(call(unpickled), out, "pickle round trip", atol=0.0, rtol=0.0)

    if check_compile:
        # A fresh Dynamo cache: each module is compiled from scratch, so no earlier test's
        # graphs (or its recompilation count) decide what this one runs.
        torch._dynamo.reset()
        compiled = torch.compile(module, backend="eager")
        _assert_same(call(compiled), out, "torch.compile(backend='eager') != eager", **tol)

    if check_export:
        program = torch.export.export(module, tuple(inputs), kwargs)
        _assert_same(call(program.module()), out, "torch.export != eager", **tol)


def warp_errors(
    alpha: float, thetas: Sequence[float], obj: Any, camera: Any, corr: Any, warp: Any = None
) -> list[float]:
    """Mean absolute error per angle of ``warp``'s views from renders at 0 and ``alpha``
    against renders at ``thetas``, over the pixels both seed views see (the paper's
    per-pixel error; intensities in [0, 1])."""
    from torch_eigview.datasets import render, seen_error
    from torch_eigview.warp.novel_view import NovelViewWarp

    r1, r2 = render(obj, 0.0, camera), render(obj, alpha, camera)
    warp = NovelViewWarp(alpha) if warp is None else warp
    views = warp(r1.image, r2.image, correspondence=corr, thetas=list(thetas))
    return [seen_error(obj, camera, views[i], theta, (0.0, alpha)) for i, theta in enumerate(thetas)]


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Runs ``eigview`` in process: its exit status (argparse's and errors' included), stdout, stderr."""
    from torch_eigview.apps.cli import main

    try:
        code = main(argv)
    except SystemExit as exc:
        code = int(exc.code)  # type: ignore[arg-type]
    out = capsys.readouterr()
    return code, out.out, out.err


def smooth_views(obj: int, n_views: int = 41, channels: int = 1, size: int = 128) -> torch.Tensor:
    """(n_views, channels, size, size) float32 random smooth views of synthetic object ``obj``.

    A random low-resolution texture (seeded by ``obj``) is upsampled bicubically to
    ``size`` × (``size`` + ``n_views``) and view t is the window starting at column t: the
    object slides by one pixel per view, so consecutive views are correlated like a
    turntable sequence. Deterministic: the same call gives the same views.
    """
    gen = torch.Generator().manual_seed(1_000_003 * obj + 17)
    low = torch.rand(1, channels, 8, 8 + max(1, (8 * n_views) // size), generator=gen)
    wide = F.interpolate(low, size=(size, size + n_views), mode="bicubic", align_corners=False)[0]
    cols = torch.arange(size)[None, :] + torch.arange(n_views)[:, None]  # (T, size)
    return wide[:, :, cols].permute(2, 0, 1, 3).contiguous().clamp_(0, 1)


def rendered_turntable(root: Any, azimuths: Sequence[float], side: int = 32) -> Any:
    """``root``/views.csv listing the rendered egg and head at ``azimuths`` (degrees), as 8-bit
    gray PNGs ``{object}/{azimuth % 360}.png``, ``side`` pixels square; returns its path."""
    from pathlib import Path

    import numpy as np
    import skimage.io

    from torch_eigview.datasets import OrthographicCamera, make_object, render_views

    root = Path(root)
    rows = ["path,object,azimuth"]
    for name in ("egg", "head"):
        images = render_views(make_object(name, seed=1), list(azimuths), OrthographicCamera(side))
        (root / name).mkdir(parents=True, exist_ok=True)
        for az, image in zip(azimuths, images, strict=True):
            pixels = (image[0].clamp(0, 1).numpy() * 255).round().astype(np.uint8)
            skimage.io.imsave(root / name / f"{az % 360:g}.png", pixels, check_contrast=False)
            rows.append(f"{name}/{az % 360:g}.png,{name},{az:g}")
    (root / "views.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    return root / "views.csv"
