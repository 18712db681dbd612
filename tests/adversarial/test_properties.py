"""Property-based tests over the public API's tensor and parameter space.

Every call either succeeds with finite output or raises ValueError/TypeError whose message
names the argument at fault: never another exception, a NaN result, or a message naming an
internal variable. Derandomized with bounded examples, so the suite is deterministic and
fast (a few seconds per property).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from torch_eigview.datasets.coil import parse_object_spec
from torch_eigview.decomposition import Eigenspace, KernelEigenspace, StreamingEigenspace
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.geometry.correspondence import correspondence_from_disparity
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.pose import orthographic_coefficients
from torch_eigview.nn.recognition import NearestNeighborRecognizer
from torch_eigview.synthesis import SynthesisOptions, pair_of, synthesize_views

PROPERTY = settings(
    derandomize=True,
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    database=None,
)

SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.5, math.nan, math.inf, -math.inf, 1e38, -1e38, 1e-40, 1e300, 3.4e38]
numbers = st.one_of(
    st.sampled_from(SPECIAL), st.floats(allow_nan=True, allow_infinity=True), st.integers(-1000, 1000)
)
oddities = st.one_of(st.none(), st.text(max_size=3), st.booleans(), st.lists(st.floats(), max_size=2))
anything = st.one_of(numbers, oddities)


@st.composite
def tensors(draw: st.DrawFn, min_dims: int = 0, max_dims: int = 4, max_side: int = 6) -> torch.Tensor:
    """A tensor of a random shape (sides 0..max_side), dtype and fill (ordinary or extreme)."""
    shape = draw(st.lists(st.integers(0, max_side), min_size=min_dims, max_size=max_dims))
    dtype = draw(st.sampled_from([torch.float32, torch.float64, torch.float16, torch.int64, torch.bool]))
    seed = draw(st.integers(0, 2**16))
    base = torch.rand(tuple(shape), generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    fill = draw(st.sampled_from(["plain", "scaled", "special"]))
    if fill == "scaled":
        base = base * draw(st.sampled_from([1e-30, 1e-20, 1e20, 1e40]))
    elif fill == "special" and base.numel():
        base.view(-1)[draw(st.integers(0, base.numel() - 1))] = draw(st.sampled_from(SPECIAL))
    if dtype == torch.bool:
        return base > 0.5
    if dtype == torch.int64:
        return torch.nan_to_num(base * 10, nan=0.0, posinf=0.0, neginf=0.0).clamp(-1e6, 1e6).to(dtype)
    return base.to(dtype)


def _finite(out: Any) -> bool:
    if isinstance(out, torch.Tensor):
        return not out.is_floating_point() or bool(torch.isfinite(out).all())
    if isinstance(out, (tuple, list)):
        return all(_finite(o) for o in out)
    if hasattr(out, "__dataclass_fields__"):
        return all(_finite(getattr(out, f)) for f in out.__dataclass_fields__)
    if isinstance(out, float):
        return math.isfinite(out)
    return True


def holds(call: Callable[[], Any], names: Sequence[str], finite: bool = True) -> None:
    """The property: a finite result (any result with ``finite=False``: a configuration may
    hold inf, e.g. ``max_stretch``), or a ValueError/TypeError that names one of ``names``."""
    try:
        out = call()
    except (ValueError, TypeError) as exc:
        message = str(exc)
        assert any(n in message for n in names), f"{type(exc).__name__} names none of {names}: {message}"
        return
    assert not finite or _finite(out), f"a non-finite result without an error: {out!r}"


@PROPERTY
@given(x=tensors(), k=anything)
def test_eigenspace_fit_and_transform(x: torch.Tensor, k: object) -> None:
    def call() -> Any:
        es = Eigenspace(k).fit(x)  # type: ignore[arg-type]
        return es.eigenvalues_, es.transform(x), es.transform(x[:0])

    holds(call, ["X", "n_components"])


@PROPERTY
@given(x=tensors(), k=st.integers(1, 3), method=st.sampled_from(["exact", "randomized"]), seed=anything)
def test_streaming_fit(x: torch.Tensor, k: int, method: str, seed: object) -> None:
    holds(
        lambda: StreamingEigenspace(k, solver=method, seed=seed).fit(x).components_,
        ["blocks", "seed", "n_components", "views"],
    )  # type: ignore[arg-type]


@PROPERTY
@given(
    x=tensors(min_dims=2, max_dims=2),
    kernel=st.sampled_from(["rbf", "poly", "cosine", "linear"]),
    gamma=anything,
)
def test_kernel_fit(x: torch.Tensor, kernel: str, gamma: object) -> None:
    def call() -> Any:
        kp = KernelEigenspace(2, kernel=kernel, gamma=gamma).fit(x)  # type: ignore[arg-type]
        return kp.transform(x)

    holds(call, ["X", "gamma", "kernel", "n_components"])


@settings(PROPERTY, max_examples=60)
@given(v1=tensors(min_dims=3, max_dims=4, max_side=7), threshold=anything, same=st.booleans())
def test_estimate_correspondence(v1: torch.Tensor, threshold: object, same: bool) -> None:
    v2 = v1 if same else v1.flip(-1)
    holds(
        lambda: estimate_correspondence(v1, v2, method="ilk", threshold=threshold),
        ["view1", "view2", "threshold"],
    )  # type: ignore[arg-type]


@PROPERTY
@given(d=tensors(min_dims=1, max_dims=4), valid=st.one_of(st.none(), tensors()), threshold=anything)
def test_correspondence_from_disparity(
    d: torch.Tensor, valid: torch.Tensor | None, threshold: object
) -> None:
    holds(
        lambda: correspondence_from_disparity(d, valid_12=valid, threshold=threshold),  # type: ignore[arg-type]
        ["disparity_12", "valid_12", "threshold"],
    )


@PROPERTY
@given(thetas=st.one_of(anything, tensors(max_dims=2)), alpha=anything)
def test_orthographic_coefficients(thetas: object, alpha: object) -> None:
    holds(lambda: orthographic_coefficients(thetas, alpha), ["thetas", "alpha"])  # type: ignore[arg-type]


@PROPERTY
@given(thetas=st.one_of(anything, tensors(max_dims=1)), alpha=anything, n=anything)
def test_pair_of(thetas: object, alpha: object, n: object) -> None:
    holds(lambda: pair_of(thetas, alpha, n), ["thetas", "alpha", "n_seeds"])  # type: ignore[arg-type]


@settings(PROPERTY, max_examples=60)
@given(seeds=tensors(min_dims=4, max_dims=4, max_side=5), alpha=anything, thetas=anything)
def test_synthesize_views(seeds: torch.Tensor, alpha: object, thetas: object) -> None:
    opts = SynthesisOptions(flow="ilk", elevation=0.0)
    holds(lambda: synthesize_views(seeds, alpha, thetas, opts).views, ["seeds", "alpha", "thetas", "view1"])  # type: ignore[arg-type]


@PROPERTY
@given(
    field=st.sampled_from(["threshold", "elevation", "background", "center", "max_stretch", "flow", "blend"]),
    value=anything,
)
def test_synthesis_options(field: str, value: object) -> None:
    holds(lambda: SynthesisOptions(**{field: value}), [field], finite=False)


@PROPERTY
@given(
    field=st.sampled_from(["alpha", "center", "synth", "test", "components", "views", "method"]),
    value=st.one_of(anything, st.tuples(numbers, numbers, numbers), st.tuples(numbers, numbers)),
)
def test_coil_experiment_arguments(field: str, value: object) -> None:
    names = {"components": "n_components"}
    holds(lambda: CoilExperiment(**{field: value}), [field, names.get(field, field)])


@PROPERTY
@given(spec=st.one_of(st.text(alphabet="0123456789-, x", max_size=14), anything))
def test_parse_object_spec(spec: object) -> None:
    holds(lambda: parse_object_spec(spec), ["spec"])  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def recognizer() -> NearestNeighborRecognizer:
    gen = torch.Generator().manual_seed(0)
    views = torch.rand(6, 1, 3, 4, generator=gen)
    projection = Eigenspace(3).fit(views).to_module(unit_norm=True)
    return NearestNeighborRecognizer.from_views(projection, views, torch.arange(6) % 3, torch.arange(6.0))


@PROPERTY
@given(x=tensors(max_side=4))
def test_recognizer_predict(recognizer: NearestNeighborRecognizer, x: torch.Tensor) -> None:
    holds(lambda: recognizer.predict(x), ["x"])
