"""``KernelProjection`` built from sizes: a fitted layer's ``state_dict`` loads into a fresh one.

The kernel maths, the fit and the module checks are tested with the estimator in
``tests/decomposition/test_kernel.py``.
"""

from __future__ import annotations

import io

import pytest
import torch

from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.nn.kernel_projection import KernelProjection

IMAGE_SHAPE = (1, 3, 4)
N_VECTORS, N_FEATURES, K = 10, 12, 3


def views(n: int, seed: int) -> torch.Tensor:
    return torch.rand(n, *IMAGE_SHAPE, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


@pytest.mark.parametrize("kernel", ["poly", "rbf"])
def test_state_dict_loads_into_a_layer_built_from_sizes(kernel: str) -> None:
    fitted = KernelEigenspace(K, kernel=kernel, gamma=0.3).fit(views(N_VECTORS, 0)).to_module(unit_norm=True)
    buffer = io.BytesIO()
    torch.save(fitted.state_dict(), buffer)
    buffer.seek(0)
    fresh = KernelProjection(N_VECTORS, N_FEATURES, K, dtype=torch.float64)
    assert fresh.kernel == "rbf" and float(fresh.vectors.abs().sum()) == 0.0
    fresh.load_state_dict(torch.load(buffer, weights_only=True))
    assert fresh.kernel == kernel and fresh.gamma == 0.3 and fresh.unit_norm
    assert fresh.image_shape == IMAGE_SHAPE and repr(fresh) == repr(fitted)
    x = views(4, 1)
    torch.testing.assert_close(fresh(x), fitted(x), atol=0, rtol=0)


def test_from_tensors_and_sizes_validation() -> None:
    vectors, coefficients, kernel_mean = torch.eye(4), torch.ones(4, 2) / 4, torch.full((4,), 0.25)
    a = KernelProjection.from_tensors(vectors, coefficients, kernel_mean, kernel="linear")
    with pytest.warns(DeprecationWarning, match=r"KernelProjection\.from_tensors\(vectors, coefficients"):
        b = KernelProjection(vectors, coefficients, kernel_mean, "linear")  # the old tensor form
    x = torch.rand(3, 4, generator=torch.Generator().manual_seed(2))
    torch.testing.assert_close(a(x), b(x), atol=0, rtol=0)
    assert KernelProjection(4, 4, 2).coefficients.shape == (4, 2)
    with pytest.raises(ValueError, match=r"n_vectors=0 must be >= 1"):
        KernelProjection(0, 4, 2)
    with pytest.raises(TypeError, match=r"n_components must be an integer, got Tensor"):
        KernelProjection(4, 4, kernel_mean)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"eigenvalues must be None when the layer is built from sizes"):
        KernelProjection(4, 4, 2, eigenvalues=torch.ones(2))
    with pytest.raises(TypeError, match=r"kernel_mean must be a torch\.Tensor, got int"):
        KernelProjection.from_tensors(vectors, coefficients, 4)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"vectors must be a torch\.Tensor, got int"):
        KernelProjection.from_tensors(4, coefficients, kernel_mean)  # type: ignore[arg-type]
