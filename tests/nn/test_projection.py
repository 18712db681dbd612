"""Tests for ``EigenProjection``: the module checks (see STYLE.md) plus ONNX against eager."""

from __future__ import annotations

import io
import pickle

import numpy as np
import pytest
import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.nn.projection import EigenProjection

IMAGE_SHAPE = (1, 4, 6)
N_FEATURES = 24
K = 5
DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def make_estimator(dtype: torch.dtype = torch.float32) -> tuple[Eigenspace, torch.Tensor]:
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(16, *IMAGE_SHAPE, generator=gen, dtype=torch.float64).to(dtype)
    return Eigenspace(K).fit(x), x


def make_module(dtype: torch.dtype = torch.float32) -> EigenProjection:
    return make_estimator(dtype)[0].to_module().eval()


def random_views(batch: int, dtype: torch.dtype = torch.float32, seed: int = 1) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.randn(batch, *IMAGE_SHAPE, generator=gen, dtype=torch.float64).to(dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_equals_eigenspace_transform(dtype: torch.dtype) -> None:
    est, x = make_estimator(dtype)
    module = est.to_module()
    torch.testing.assert_close(module(x), est.transform(x))
    torch.testing.assert_close(module(x.flatten(1)), module(x))
    torch.testing.assert_close(
        module.reconstruct(module(x)), est.inverse_transform(est.transform(x)).reshape(x.shape)
    )


@pytest.mark.parametrize("device", DEVICES)
def test_module_invariants(device: str) -> None:
    module = make_module(torch.float64).to(device)
    x = random_views(7, torch.float64).to(device)
    before = x.clone()
    z = module(x)
    assert z.shape == (7, K) and z.dtype == torch.float64 and z.device == x.device
    torch.testing.assert_close(x, before, atol=0, rtol=0)  # input not modified
    per_sample = torch.cat([module(x[i : i + 1]) for i in range(x.shape[0])])
    torch.testing.assert_close(z, per_sample)
    assert module(x[:0]).shape == (0, K)
    assert module(x[:0].flatten(1)).shape == (0, K)
    assert module.reconstruct(z[:0]).shape == (0, *IMAGE_SHAPE)


def test_gradients_reach_the_input_only() -> None:
    module = make_module(torch.float64)
    assert list(module.parameters()) == []
    assert {name for name, _ in module.named_buffers()} == {"mean", "components", "eigenvalues"}
    x = random_views(3, torch.float64).requires_grad_(True)
    module(x).sum().backward()
    assert x.grad is not None
    expected = module.components.sum(0).reshape(IMAGE_SHAPE).expand_as(x)
    torch.testing.assert_close(x.grad, expected)
    assert all(b.grad is None and not b.requires_grad for b in module.buffers())
    assert torch.autograd.gradcheck(module, (random_views(2, torch.float64).requires_grad_(True),))


def test_dtype_conversion() -> None:
    module = make_module(torch.float32)
    x = random_views(3, torch.float32)
    double = make_module(torch.float32).double()
    assert all(b.dtype == torch.float64 for b in double.buffers())
    torch.testing.assert_close(double(x.double()), module(x).double(), atol=1e-5, rtol=1e-5)
    half = make_module(torch.float32).to(torch.float64)
    assert half.components.dtype == torch.float64
    # Any floating input is cast to the buffers' dtype, as a drop-in layer should take it.
    torch.testing.assert_close(double(x), double(x.double()), atol=0, rtol=0)
    assert double(x).dtype == torch.float64
    torch.testing.assert_close(module(x.double()), module(x), atol=0, rtol=0)
    assert module(x.to(torch.bfloat16)).dtype == torch.float32
    with pytest.raises(TypeError, match=r"x must have a floating dtype .* got torch\.uint8"):
        module((x * 255).to(torch.uint8))


@pytest.mark.parametrize("low", [torch.bfloat16, torch.float16])
def test_autocast_and_low_precision_inputs(low: torch.dtype) -> None:
    module = make_module(torch.float32)
    x = random_views(3, torch.float32)
    reference = module(x)
    # A bfloat16 or float16 batch (what autocast's layers give) projects as its float32 cast.
    torch.testing.assert_close(module(x.to(low)), module(x.to(low).float()), atol=0, rtol=0)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        z = module(x.to(low))
    assert z.dtype == torch.bfloat16  # autocast runs the matrix product in its dtype
    torch.testing.assert_close(z.float(), reference, atol=0.05, rtol=0.05)
    back = module.reconstruct(reference.to(low))
    assert back.dtype == torch.float32


def test_state_dict_round_trip() -> None:
    module = make_module()
    state = module.state_dict()
    assert {"mean", "components", "eigenvalues"} <= set(state)
    buffer = io.BytesIO()
    torch.save(state, buffer)
    buffer.seek(0)
    loaded = torch.load(buffer, weights_only=True)
    fresh = EigenProjection.from_tensors(torch.zeros(N_FEATURES), torch.zeros(K, N_FEATURES), torch.zeros(K))
    assert fresh.image_shape is None
    fresh.load_state_dict(loaded)
    assert fresh.image_shape == IMAGE_SHAPE  # restored from the extra state
    x = random_views(4)
    torch.testing.assert_close(fresh(x), module(x), atol=0, rtol=0)


def test_pickle_round_trip() -> None:
    module = make_module()
    buffer = io.BytesIO()
    torch.save(module, buffer)
    buffer.seek(0)
    loaded = torch.load(buffer, weights_only=False)
    x = random_views(4)
    torch.testing.assert_close(loaded(x), module(x), atol=0, rtol=0)
    assert loaded.image_shape == IMAGE_SHAPE
    again = pickle.loads(pickle.dumps(module))
    torch.testing.assert_close(again(x), module(x), atol=0, rtol=0)


@pytest.mark.filterwarnings("ignore:`torch.jit.trace:DeprecationWarning")
def test_trace_export_and_compile_equal_eager() -> None:
    module = make_module()
    traced = torch.jit.trace(module, (random_views(3),))
    exported = torch.export.export(
        module, (random_views(3),), dynamic_shapes=({0: torch.export.Dim("batch")},)
    ).module()
    # aot_eager with fullgraph=True proves the forward captures as one graph (no breaks)
    # without needing a C++ toolchain; inductor adds ~25 s of CPU compile for nothing here.
    compiled = torch.compile(module, backend="aot_eager", fullgraph=True)
    for batch in (1, 5):
        x = random_views(batch, seed=batch)
        torch.testing.assert_close(traced(x), module(x))
        torch.testing.assert_close(exported(x), module(x))
        torch.testing.assert_close(compiled(x), module(x))


def test_repr_and_properties() -> None:
    module = make_module()
    assert module.in_features == N_FEATURES and module.n_components == K
    assert f"in_features={N_FEATURES}, n_components={K}, image_shape=(1, 4, 6)" in repr(module)
    bare = EigenProjection.from_tensors(torch.zeros(3), torch.eye(3)[:2])
    assert repr(bare) == "EigenProjection(in_features=3, n_components=2)"
    assert bare.eigenvalues.shape == (0,)
    assert bare.reconstruct(torch.zeros(4, 2)).shape == (4, 3)


def test_wrong_input_shapes() -> None:
    module = make_module()
    with pytest.raises(
        ValueError, match=r"x must have shape \(B, 24\) or \(B, 1, 4, 6\), got shape \(2, 25\)"
    ):
        module(torch.zeros(2, 25))
    with pytest.raises(ValueError, match=r"\(B, 1, 4, 6\), got shape \(2, 1, 6, 4\)"):
        module(torch.zeros(2, 1, 6, 4))
    with pytest.raises(ValueError, match=r"got shape \(2, 4, 6\)"):
        module(torch.zeros(2, 4, 6))
    with pytest.raises(TypeError, match=r"x must be a torch\.Tensor"):
        module(np.zeros((2, 24)))
    with pytest.raises(ValueError, match=r"z must have shape \(B, 5\), got shape \(2, 4\)"):
        module.reconstruct(torch.zeros(2, 4))


def test_constructor_validation() -> None:
    mean, comps = torch.zeros(6), torch.eye(6)[:2]
    with pytest.raises(ValueError, match=r"mean must have shape \(6,\).*got \(5,\)"):
        EigenProjection.from_tensors(torch.zeros(5), comps)
    with pytest.raises(ValueError, match=r"components must have shape \(k, N\)"):
        EigenProjection.from_tensors(mean, torch.zeros(6))
    with pytest.raises(ValueError, match=r"eigenvalues must have shape \(2,\)"):
        EigenProjection.from_tensors(mean, comps, torch.ones(3))
    with pytest.raises(TypeError, match=r"components must have dtype torch\.float32"):
        EigenProjection.from_tensors(mean, comps.double())
    with pytest.raises(TypeError, match=r"mean must be a torch\.Tensor"):
        EigenProjection.from_tensors([0.0] * 6, comps)  # type: ignore[arg-type]
    bad = comps.clone()
    bad[0, 0] = float("nan")
    with pytest.raises(ValueError, match="components must be finite"):
        EigenProjection.from_tensors(mean, bad)
    with pytest.raises(
        ValueError, match=r"image_shape=\(1, 2, 2\) must be positive with C\*H\*W equal to the 6"
    ):
        EigenProjection.from_tensors(mean, comps, image_shape=(1, 2, 2))
    with pytest.raises(TypeError, match="image_shape must be None or a"):
        EigenProjection.from_tensors(mean, comps, image_shape=(6,))  # type: ignore[arg-type]
    # The layer copies its inputs.
    module = EigenProjection.from_tensors(mean, comps)
    mean += 1.0
    assert float(module.mean.abs().sum()) == 0.0


@pytest.mark.filterwarnings("ignore::UserWarning", "ignore::FutureWarning", "ignore::DeprecationWarning")
def test_onnx_matches_eager(tmp_path) -> None:
    onnxruntime = pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    module = make_module(torch.float32)
    path = tmp_path / "projection.onnx"
    batch = torch.export.Dim("batch")
    torch.onnx.export(
        module,
        (random_views(2),),
        str(path),
        dynamo=True,
        dynamic_shapes=({0: batch},),
        opset_version=18,
        verbose=False,
    )
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    name = session.get_inputs()[0].name
    for size in (1, 5):
        x = random_views(size, seed=10 + size)
        (actual,) = session.run(None, {name: x.numpy()})
        expected = module(x).detach().numpy()
        assert actual.shape == (size, K)
        rel = np.abs(actual - expected).max() / np.abs(expected).max()
        assert rel <= 1e-5


# --- built from sizes, as FrozenBatchNorm2d: a state_dict loads into a fresh layer -----------


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("eigenvalues", [True, False], ids=["eigenvalues", "no-eigenvalues"])
def test_state_dict_loads_into_a_layer_built_from_sizes(dtype: torch.dtype, eigenvalues: bool) -> None:
    est, x = make_estimator(dtype)
    fitted = EigenProjection.from_tensors(
        est.mean_, est.components_, est.eigenvalues_ if eigenvalues else None, IMAGE_SHAPE, unit_norm=True
    )
    buffer = io.BytesIO()
    torch.save(fitted.state_dict(), buffer)
    buffer.seek(0)
    fresh = EigenProjection(N_FEATURES, K, image_shape=IMAGE_SHAPE, dtype=dtype)
    assert float(fresh.components.abs().sum()) == 0.0 and fresh.eigenvalues.shape == (0,)
    assert not fresh.unit_norm
    fresh.load_state_dict(torch.load(buffer, weights_only=True))
    assert fresh.unit_norm and fresh.image_shape == IMAGE_SHAPE  # restored from the extra state
    assert torch.equal(fresh.eigenvalues, fitted.eigenvalues)
    torch.testing.assert_close(fresh(x), fitted(x), atol=0, rtol=0)
    torch.testing.assert_close(fresh.reconstruct(fresh(x)), fitted.reconstruct(fitted(x)), atol=0, rtol=0)
    # The extra state brings image_shape to a layer built without one.
    bare = EigenProjection(N_FEATURES, K, dtype=dtype)
    bare.load_state_dict(fitted.state_dict())
    assert bare.image_shape == IMAGE_SHAPE and repr(bare) == repr(fitted)


def test_sizes_form_defaults_and_the_tensor_form() -> None:
    fresh = EigenProjection(N_FEATURES, K)
    assert fresh.mean.dtype == torch.get_default_dtype() and fresh.mean.device.type == "cpu"
    assert fresh.mean.shape == (N_FEATURES,) and fresh.components.shape == (K, N_FEATURES)
    assert repr(fresh) == f"EigenProjection(in_features={N_FEATURES}, n_components={K})"
    assert EigenProjection(N_FEATURES, K, dtype=torch.float64).components.dtype == torch.float64
    # Tensors go to from_tensors; the constructor's old tensor form builds the same layer
    # with a DeprecationWarning. dtype converts either.
    est, x = make_estimator(torch.float64)
    a = EigenProjection.from_tensors(est.mean_, est.components_, est.eigenvalues_, IMAGE_SHAPE)
    with pytest.warns(DeprecationWarning, match=r"EigenProjection\.from_tensors\(mean, components"):
        b = EigenProjection(est.mean_, est.components_, est.eigenvalues_, IMAGE_SHAPE)
    torch.testing.assert_close(a(x), b(x), atol=0, rtol=0)
    c = EigenProjection.from_tensors(est.mean_, est.components_, dtype=torch.float32)
    assert c.mean.dtype == torch.float32 and est.mean_.dtype == torch.float64


def test_sizes_form_validation() -> None:
    with pytest.raises(ValueError, match=r"n_features=0 must be >= 1"):
        EigenProjection(0, 2)
    with pytest.raises(ValueError, match=r"n_components=0 must be >= 1"):
        EigenProjection(6, 0)
    with pytest.raises(TypeError, match=r"n_components must be an integer, got float 2\.0"):
        EigenProjection(6, 2.0)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"eigenvalues must be None when the layer is built from sizes"):
        EigenProjection(6, 2, torch.ones(2))
    with pytest.raises(
        ValueError, match=r"image_shape=\(1, 2, 2\) must be positive with C\*H\*W equal to the 6"
    ):
        EigenProjection(6, 2, image_shape=(1, 2, 2))
    with pytest.raises(TypeError, match=r"mean must be a torch\.Tensor, got int"):
        EigenProjection.from_tensors(6, torch.eye(6)[:2])  # type: ignore[arg-type]
    # A state_dict of other sizes is refused by load_state_dict; eigenvalues of a third shape too.
    fitted = make_module()
    with pytest.raises(RuntimeError, match=r"size mismatch for components"):
        EigenProjection(N_FEATURES, K + 1).load_state_dict(fitted.state_dict())
    state = fitted.state_dict()
    state["eigenvalues"] = torch.ones(K + 2)
    with pytest.raises(RuntimeError, match=r"size mismatch for eigenvalues"):
        EigenProjection(N_FEATURES, K).load_state_dict(state)
