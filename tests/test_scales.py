"""Valid views at extreme scales (issue 41, class 3): with unit-norm brightness
normalization a view and any positive multiple of it are the same view, so every
unit-norm path gives the same codes, labels and distances at scales 1e-30 … 1e30, in
float32 and float64, eagerly and through onnxruntime: within 1e-5 relative."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime
import pytest
import torch

from torch_eigview import Eigenspace, FewViewEigenspace, KernelEigenspace
from torch_eigview.datasets import OrthographicCamera, make_object, render_views
from torch_eigview.io.onnx import export_projection, export_recognizer
from torch_eigview.sklearn import EigenspaceKernelPCA, EigenspacePCA

SCALES = (1e-30, 1e-20, 1e-8, 1e8, 1e20, 1e30)
DTYPES = (torch.float32, torch.float64)
SHAPE = (1, 16, 16)


def _close_distances(
    got: torch.Tensor | np.ndarray, want: torch.Tensor, codes: torch.Tensor, what: str
) -> None:
    """Squared distances within 1e-5 of the codes' squared norm: a distance is computed as
    ‖z‖² − 2 z·c + ‖c‖², so a small one carries the codes' rounding times ‖z‖/d; its
    square is what the codes determine to 1e-5."""
    got, want = torch.as_tensor(got).double(), want.double()
    _close(got.square(), want.square(), what, scale=float(codes.double().square().sum(dim=1).max()))


def _views(n: int, seed: int, dtype: torch.dtype) -> torch.Tensor:
    x = torch.rand(n, *SHAPE, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return x.to(dtype)


def _close(
    got: torch.Tensor | np.ndarray, want: torch.Tensor | np.ndarray, what: str, scale: float | None = None
) -> None:
    """``got`` equals ``want`` within 1e-5 of ``scale`` (default: ``want``'s largest magnitude)."""
    got, want = torch.as_tensor(got).double(), torch.as_tensor(want).double()
    assert bool(torch.isfinite(got).all()), f"{what}: non-finite values"
    scale = float(want.abs().max()) if scale is None else scale
    err = float((got - want).abs().max()) / max(scale, 1e-300)
    assert err <= 1e-5, f"{what}: relative error {err:.3g}"


@pytest.mark.parametrize("dtype", DTYPES, ids=["float32", "float64"])
@pytest.mark.parametrize("kernel", [None, "rbf", "cosine"])
def test_unit_norm_layer_any_scale(dtype: torch.dtype, kernel: str | None) -> None:
    """The issue's reproduction, and the kernel layers: codes of x·s equal codes of x."""
    x = _views(36, 0, dtype)
    if kernel is None:
        layer = Eigenspace(5).fit(x / x.flatten(1).norm(dim=1).view(-1, 1, 1, 1))
        p = layer.to_module(unit_norm=True, image_shape=SHAPE)
    else:
        p = KernelEigenspace(5, kernel=kernel).fit(x.flatten(1)).to_module(unit_norm=True)
    want = p(x[:4])
    for s in SCALES:
        _close(p(x[:4] * s), want, f"scale {s:g}")


@pytest.fixture(scope="module")
def seeds() -> torch.Tensor:
    camera = OrthographicCamera(16)
    return torch.stack(
        [render_views(make_object(n), [0.0, 10.0], camera) for n in ("ellipsoid", "egg", "head")]
    )


@pytest.mark.parametrize("dtype", DTYPES, ids=["float32", "float64"])
def test_estimator_transform_and_predict_any_scale(seeds: torch.Tensor, dtype: torch.dtype) -> None:
    est = FewViewEigenspace(6).fit(seeds.to(dtype), [0.0, 10.0], labels=[1, 2, 3])
    x = seeds[:, 0].to(dtype) * 0.5 + seeds[:, 1].to(dtype) * 0.5
    codes, ref = est.transform(x), est.predict(x)
    for s in SCALES:
        _close(est.transform(x * s), codes, f"transform at scale {s:g}")
        got = est.predict(x * s)
        assert torch.equal(got.labels, ref.labels), f"labels at scale {s:g}"
        _close_distances(got.distances, ref.distances, codes, f"distances at scale {s:g}")


@pytest.mark.parametrize("cls", [EigenspacePCA, EigenspaceKernelPCA])
def test_sklearn_adapters_any_scale(cls: type) -> None:
    x = _views(30, 1, torch.float64).flatten(1).numpy()
    est = cls(n_components=4, unit_norm=True).fit(x)
    want = est.transform(x[:5])
    for s in SCALES:
        _close(est.transform(x[:5] * s), want, f"{cls.__name__} at scale {s:g}")


@pytest.mark.parametrize("fold", [True, False], ids=["folded", "unfolded"])
def test_onnx_any_scale(tmp_path: Path, seeds: torch.Tensor, fold: bool) -> None:
    """The exported graphs (projection, and the recognizer's labels and distances) at every
    scale, against eager torch at scale 1."""
    est = FewViewEigenspace(6).fit(seeds, [0.0, 10.0], labels=[1, 2, 3])
    export_projection(est.projection_, tmp_path / "p.onnx", fold=fold)
    export_recognizer(est.recognizer_, tmp_path / "r.onnx")
    proj = onnxruntime.InferenceSession(str(tmp_path / "p.onnx"), providers=["CPUExecutionProvider"])
    rec = onnxruntime.InferenceSession(str(tmp_path / "r.onnx"), providers=["CPUExecutionProvider"])
    x = seeds[:, 0] * 0.5 + seeds[:, 1] * 0.5
    codes, ref = est.transform(x), est.predict(x)
    for s in SCALES:
        feed = {"images": (x * s).numpy().astype(np.float32)}
        _close(proj.run(None, feed)[0], codes, f"onnx projection at scale {s:g}")
        out = dict(zip([o.name for o in rec.get_outputs()], rec.run(None, feed), strict=True))
        labels = np.array([1, 2, 3])[out["label_index"]]  # indices into the sorted labels
        assert np.array_equal(labels, ref.labels.numpy()), f"onnx labels at scale {s:g}"
        _close_distances(out["distance"], ref.distances, codes, f"onnx distances at scale {s:g}")


@pytest.mark.parametrize("dtype", DTYPES, ids=["float32", "float64"])
def test_unit_rows_both_paths(dtype: torch.dtype) -> None:
    """Eagerly, ordinary rows take the plain norm and a batch with a row past it (huge,
    tiny, all zero) the scaled one: both agree with float64 arithmetic on the rows; a zero
    row stays zero."""
    from torch_eigview.nn import unit_rows

    x = _views(3, 2, dtype).flatten(1)
    want = x.double() / x.double().norm(dim=1, keepdim=True)
    _close(unit_rows(x), want, "plain rows")
    for odd in (x[:1] * 1e30, x[:1] * 1e-30, torch.zeros_like(x[:1])):
        got = unit_rows(torch.cat([x, odd]))
        _close(got[:3], want, "rows beside an odd one")
        if not bool(odd.any()):
            assert not bool(got[3].any())
        else:
            _close(got[3], want[0], "the odd row")
