"""``check_module`` on every ``nn.Module`` class of the package.

The classes are found by walking the package, so a new module fails
:func:`test_every_module_class_has_a_case` until a case below builds it. Each case makes a
small instance through public constructors and estimators only, on seeded data.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
from collections.abc import Callable
from typing import Any

import pytest
import torch

import torch_eigview
from torch_eigview import (
    EigenProjection,
    Eigenspace,
    KernelEigenspace,
    KernelProjection,
    NearestNeighborRecognizer,
    NovelViewWarp,
    PerspectiveWarp,
)
from torch_eigview.datasets import PerspectiveCamera, exact_correspondence_2d, make_object, render
from torch_eigview.geometry import Correspondence, correspondence_from_disparity
from torch_eigview.io.onnx import ExportedRecognizer, FoldedProjection
from torch_eigview.warp import RandomTurntableRotation

from tests.helpers import check_module, rand

IMAGE = (1, 4, 5)  # (C, H, W) of the frozen layers' views


def package_module_classes() -> set[type[torch.nn.Module]]:
    """The concrete, public ``nn.Module`` subclasses defined in ``torch_eigview``.

    Private classes (``_Name``) are implementation details of a public function, such as the
    wrapper ``io.onnx`` exports through, and are exercised by that function's tests;
    abstract bases cannot be built and are exercised through their subclasses.
    """
    found: set[type[torch.nn.Module]] = set()
    for info in pkgutil.walk_packages(torch_eigview.__path__, "torch_eigview."):
        if info.name.rsplit(".", 1)[-1] == "__main__":  # importing it runs the command
            continue
        module = importlib.import_module(info.name)
        for name, cls in inspect.getmembers(module, inspect.isclass):
            if (
                issubclass(cls, torch.nn.Module)
                and cls.__module__ == module.__name__
                and not name.startswith("_")
                and not inspect.isabstract(cls)
            ):
                found.add(cls)
    return found


@dataclasses.dataclass
class Case:
    """A module with its inputs, and how ``check_module`` should treat them."""

    module: torch.nn.Module
    inputs: tuple[Any, ...]
    kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    batched_kwargs: tuple[str, ...] = ()
    export: bool = True  # all-tensor arguments: torch.export applies


def _views(n: int, seed: int, dtype: torch.dtype) -> torch.Tensor:
    return rand(n, *IMAGE, seed=seed, dtype=dtype)


def _space(dtype: torch.dtype) -> Eigenspace:
    return Eigenspace(3).fit(_views(8, 1, dtype))


def _unit_norm_projection(dtype: torch.dtype) -> EigenProjection:
    space = _space(dtype)
    return EigenProjection.from_tensors(
        space.mean_, space.components_, space.eigenvalues_, image_shape=IMAGE, unit_norm=True
    )


def _recognizer(dtype: torch.dtype) -> NearestNeighborRecognizer:
    gallery = _views(6, 2, dtype)
    labels = torch.tensor([0, 0, 1, 1, 2, 2])
    poses = torch.tensor([-5.0, 5.0, -5.0, 5.0, -5.0, 5.0])
    return NearestNeighborRecognizer.from_views(_space(dtype).to_module(), gallery, labels, poses)


def eigen_projection(dtype: torch.dtype) -> Case:
    return Case(_space(dtype).to_module(), (_views(3, 3, dtype),))


def eigen_projection_unit_norm(dtype: torch.dtype) -> Case:
    return Case(_unit_norm_projection(dtype), (_views(3, 3, dtype),))


def kernel_projection(dtype: torch.dtype) -> Case:
    module = KernelEigenspace(3, kernel="rbf", gamma=0.5).fit(_views(8, 1, dtype)).to_module(unit_norm=True)
    return Case(module, (_views(3, 3, dtype),))


def nearest_neighbor_recognizer(dtype: torch.dtype) -> Case:
    return Case(_recognizer(dtype), (_views(3, 3, dtype),))


def folded_projection(dtype: torch.dtype) -> Case:
    return Case(FoldedProjection(_unit_norm_projection(dtype), dtype=dtype), (_views(3, 3, dtype),))


def exported_recognizer(dtype: torch.dtype) -> Case:
    return Case(ExportedRecognizer(_recognizer(dtype), dtype=dtype), (_views(3, 3, dtype),))


def novel_view_warp(dtype: torch.dtype) -> Case:
    """A tilted camera (elevation 25°), so the maps also move rows (the 2D refinement)."""
    b, c, h, w = 2, 2, 6, 9
    corr = correspondence_from_disparity((3.0 * rand(b, h, w, seed=22) - 1.5).to(dtype))
    return Case(
        NovelViewWarp(12.0, elevation=25.0),
        (rand(b, c, h, w, seed=20, dtype=dtype), rand(b, c, h, w, seed=21, dtype=dtype)),
        dict(correspondence=corr, thetas=[-5.0, 6.0, 20.0]),
        batched_kwargs=("correspondence",),
        export=False,
    )


def perspective_warp(dtype: torch.dtype) -> Case:
    """Two rendered objects (B = 2) seen by a 16×16 pinhole camera, exact 2D correspondences."""
    size, distance, alpha = 16, 4.0, 10.0
    f = 0.45 * size * distance
    k = ((f, 0.0, (size - 1) / 2), (0.0, f, (size - 1) / 2), (0.0, 0.0, 1.0))
    camera = PerspectiveCamera(size, distance, K=k)
    objects = [make_object("ellipsoid"), make_object("head")]
    seeds = [torch.stack([render(o, angle, camera).image for o in objects]) for angle in (0.0, alpha)]
    corrs = [exact_correspondence_2d(o, alpha, camera) for o in objects]
    corr = Correspondence(
        **{
            f.name: torch.cat([getattr(one, f.name) for one in corrs])
            for f in dataclasses.fields(Correspondence)
        }
    )
    return Case(
        PerspectiveWarp(alpha, torch.tensor(k, dtype=torch.float64), distance),
        (seeds[0].to(dtype), seeds[1].to(dtype)),
        dict(correspondence=corr.to(dtype=dtype), thetas=[-5.0, 4.0, 15.0]),
        batched_kwargs=("correspondence",),
        export=False,
    )


def random_turntable_rotation(dtype: torch.dtype) -> Case:
    """Replayed parameters (B different angles, one sample not turned), so that the batched
    call and the per-sample calls see the same draws."""
    b, c, h, w = 3, 2, 6, 9
    corr = correspondence_from_disparity((3.0 * rand(b, h, w, seed=25) - 1.5).to(dtype))
    params = {"degrees": torch.tensor([-6.0, 8.0, 15.0]), "batch_prob": torch.tensor([True, False, True])}
    return Case(
        RandomTurntableRotation(20.0, 12.0, elevation=25.0),
        (rand(b, c, h, w, seed=23, dtype=dtype), rand(b, c, h, w, seed=24, dtype=dtype)),
        dict(correspondence=corr, params=params),
        batched_kwargs=("correspondence", "params"),
        export=False,
    )


BOTH = (torch.float32, torch.float64)

# name -> (class, case factory, dtypes, slow); a class may have several cases. The warps run
# in float32 only: Dynamo spends seconds on their Python-level map building, and
# tests/warp/test_novel_view.py checks NovelViewWarp's other invariants in both dtypes.
CASES: dict[
    str, tuple[type[torch.nn.Module], Callable[[torch.dtype], Case], tuple[torch.dtype, ...], bool]
] = {
    "EigenProjection": (EigenProjection, eigen_projection, BOTH, False),
    "EigenProjection-unit-norm": (EigenProjection, eigen_projection_unit_norm, BOTH, False),
    "KernelProjection": (KernelProjection, kernel_projection, BOTH, False),
    "NearestNeighborRecognizer": (NearestNeighborRecognizer, nearest_neighbor_recognizer, BOTH, False),
    "FoldedProjection": (FoldedProjection, folded_projection, BOTH, False),
    "ExportedRecognizer": (ExportedRecognizer, exported_recognizer, BOTH, False),
    "NovelViewWarp": (NovelViewWarp, novel_view_warp, (torch.float32,), True),
    "PerspectiveWarp": (PerspectiveWarp, perspective_warp, (torch.float32,), True),
    "RandomTurntableRotation": (RandomTurntableRotation, random_turntable_rotation, (torch.float32,), True),
}


# Base classes that only their subclasses complete (a method raises NotImplementedError);
# each is checked through the covered classes derived from it.
BASES = {"ViewWarp", "FrozenProjection"}


def test_every_module_class_has_a_case() -> None:
    covered = {cls for cls, _, _, _ in CASES.values()}
    bases = {
        c
        for c in package_module_classes()
        if c.__qualname__ in BASES and any(issubclass(sub, c) for sub in covered)
    }
    missing = sorted(c.__module__ + "." + c.__qualname__ for c in package_module_classes() - covered - bases)
    assert not missing, (
        f"nn.Module classes without a check_module case in tests/nn/test_modules.py: {missing}"
    )
    unknown = sorted(c.__qualname__ for c in covered - package_module_classes())
    assert not unknown, f"cases for classes the package does not define (renamed?): {unknown}"


@pytest.mark.parametrize(
    ("name", "dtype"),
    [
        pytest.param(name, dtype, marks=[pytest.mark.slow] if slow else [], id=f"{name}-{str(dtype)[6:]}")
        for name, (_, _, dtypes, slow) in CASES.items()
        for dtype in dtypes
    ],
)
def test_check_module(name: str, dtype: torch.dtype, device: torch.device, tol: dict[str, float]) -> None:
    cls, factory, _, _ = CASES[name]
    case = factory(dtype)
    assert type(case.module) is cls
    module = case.module.to(device)
    inputs = tuple(t.to(device) if isinstance(t, torch.Tensor) else t for t in case.inputs)
    kwargs = {
        k: v.to(device) if isinstance(v, (torch.Tensor, Correspondence)) else v
        for k, v in case.kwargs.items()
    }
    check_module(
        module,
        inputs,
        kwargs,
        batched_kwargs=case.batched_kwargs,
        tol=tol,
        check_compile=True,
        check_export=case.export,
    )
