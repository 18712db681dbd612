"""SparseViewOperator: G·C against the kornia warp, the literal Eq. 4 loop, concat, fit_sparse."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.geometry.correspondence import correspondence_from_disparity
from torch_eigview.warp.maps import WarpMaps
from torch_eigview.warp.novel_view import NovelViewWarp
from torch_eigview.warp.operator import SparseViewOperator

from tests.warp.operator_cases import (
    THETAS,
    H,
    W,
    assert_close,
    generator,
    maps_2d,
    setup,
)


# --------------------------------------------------------------------------- gather mode
@pytest.mark.parametrize("n_sources", [1, 2])
@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("amplitude", [2.5, -4.0], ids=["monotone", "folding"])
def test_from_maps_equals_kornia_warp(
    dtype: torch.dtype, channels: int, n_sources: int, amplitude: float
) -> None:
    images, maps = setup(dtype, channels, n_sources, amplitude)
    expected = NovelViewWarp.apply_maps(maps, images[:, None])[0]
    op = SparseViewOperator.from_maps(images, maps)
    assert op.n_views == len(THETAS) and op.image_shape == (channels, H, W)
    assert op.G.shape == (channels * H * W, n_sources * H * W * W)
    assert op.C.shape == (n_sources * H * W * W, len(THETAS))
    assert op.G.is_coalesced() and op.C.is_coalesced()
    assert_close(op.views(), expected, dtype)
    assert_close(op.data_matrix(), expected.reshape(len(THETAS), -1).T, dtype)


def test_from_maps_source_columns_outside_image(dtype: torch.dtype) -> None:
    """Zeros padding, exact pixel centres and edges; NaN source columns of zero weight are skipped."""
    gen = generator(1)
    s, t = 2, 4
    images = torch.rand(s, 3, H, W, generator=gen, dtype=torch.float64).to(dtype)
    src_x = torch.rand(s, 1, t, H, W, generator=gen, dtype=torch.float64) * (W + 5) - 3
    src_x[..., :6] = torch.tensor([-1.0, -0.5, 0.0, W - 1.0, W - 0.5, 3.0], dtype=torch.float64)
    weight = torch.rand(s, 1, t, H, W, generator=gen, dtype=torch.float64)
    weight[0, :, :, 0, :3] = 0.0
    src_x[0, :, :, 0, :3] = math.nan
    maps = WarpMaps(src_x.to(dtype), weight.to(dtype), weight > 0, torch.zeros(t))
    op = SparseViewOperator.from_maps(images, maps)
    # kornia turns a NaN coordinate into NaN (and NaN · 0 = NaN): give it any finite column there.
    finite = dataclasses.replace(maps, src_x=torch.nan_to_num(maps.src_x, nan=0.0))
    assert_close(op.views(), NovelViewWarp.apply_maps(finite, images[:, None])[0], dtype)
    assert op.views().isfinite().all()


def test_from_maps_casts_maps_to_image_dtype() -> None:
    images, maps = setup(torch.float64, 3, 2)
    images32 = images.float()
    op = SparseViewOperator.from_maps(images32, maps)
    assert op.G.dtype == op.C.dtype == torch.float32
    assert_close(op.views(), NovelViewWarp.apply_maps(maps, images32[:, None])[0], torch.float32)


def test_seed_matrix_layout() -> None:
    """G[(c, j, l), (s, j, l, k)] = I_s[c, j, k], nothing else."""
    gen = generator(2)
    s, c, h, w = 2, 3, 3, 4
    images = torch.rand(s, c, h, w, generator=gen, dtype=torch.float64)
    images[0, 1, 2, 3] = 0.0  # zeros are not stored
    maps = WarpMaps(
        torch.zeros(s, 1, 1, h, w), torch.ones(s, 1, 1, h, w), torch.ones(s, 1, 1, h, w) > 0, torch.zeros(1)
    )
    op = SparseViewOperator.from_maps(images, maps)
    expected = torch.zeros(c * h * w, s * h * w * w, dtype=torch.float64)
    for ci in range(c):
        for j in range(h):
            for col in range(w):
                for si in range(s):
                    for k in range(w):
                        expected[(ci * h + j) * w + col, si * h * w * w + (j * w + col) * w + k] = images[
                            si, ci, j, k
                        ]
    assert torch.equal(op.G.to_dense(), expected)
    assert op.nnz[0] == s * c * h * w * w - w  # the zero pixel is skipped in its W rows
    assert torch.equal(op.G.indices(), op.G.coalesce().indices())


# --------------------------------------------------------------------------- splat mode
def _eq4_loop(image: torch.Tensor, x3: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Eq. 3–4 literally: I3(j, l) = Σ_k I1(j, k) y_k, y_k = 1 − dist if dist < 1, dist = |x3_k − l|."""
    c, h, w = image.shape
    t = x3.shape[0]
    coeff = torch.zeros(h * w * w, t, dtype=torch.float64)
    views = torch.zeros(t, c, h, w, dtype=torch.float64)
    for ti in range(t):
        for j in range(h):
            for col in range(w):
                for k in range(w):
                    dist = abs(float(x3[ti, j, k]) - col)
                    y = 1.0 - dist if dist < 1.0 else 0.0
                    coeff[(j * w + col) * w + k, ti] = y
                    for ci in range(c):
                        views[ti, ci, j, col] += float(image[ci, j, k]) * y
    return coeff, views


@pytest.mark.parametrize("channels", [1, 3])
def test_from_forward_map_equals_eq4_loop(channels: int) -> None:
    gen = generator(3)
    h, w, t = 5, 7, 4
    image = torch.rand(channels, h, w, generator=gen, dtype=torch.float64)
    x1 = torch.arange(w, dtype=torch.float64).expand(h, w)
    x2 = x1 + torch.rand(h, w, generator=gen, dtype=torch.float64) * 3 - 1.5
    a = torch.tensor([1.0, 0.4, -0.3, 1.6], dtype=torch.float64).view(t, 1, 1)
    b = 1 - a
    x3 = a * x1 + b * x2  # Eq. 2, including targets outside [0, W - 1]
    x3[0, 0, :] = torch.arange(w, dtype=torch.float64) - 1.0  # exact integers: one coefficient
    coeff, views = _eq4_loop(image, x3)
    op = SparseViewOperator.from_forward_map(image, x3)
    assert op.G.shape == (channels * h * w, h * w * w) and op.C.shape == (h * w * w, t)
    assert torch.allclose(op.C.to_dense(), coeff, rtol=0, atol=1e-12)
    assert torch.allclose(op.views(), views, rtol=0, atol=1e-12)
    assert bool((op.C.values() > 0).all())


def test_from_forward_map_nan_is_no_target() -> None:
    gen = generator(4)
    image = torch.rand(1, 4, 6, generator=gen, dtype=torch.float64)
    x3 = torch.arange(6, dtype=torch.float64).expand(2, 4, 6) + 0.25
    x3_nan = x3.clone()
    x3_nan[:, :, 2] = math.nan
    image_zero = image.clone()
    image_zero[:, :, 2] = 0.0
    expected = SparseViewOperator.from_forward_map(image_zero, x3).views()
    torch.testing.assert_close(SparseViewOperator.from_forward_map(image, x3_nan).views(), expected)


# --------------------------------------------------------------------------- several objects
def test_concat_is_views_side_by_side(dtype: torch.dtype) -> None:
    img_a, maps_a = setup(dtype, 3, 2, seed=5)
    img_b, maps_b = setup(dtype, 3, 1, seed=6)
    img_c = torch.rand(3, H, W, generator=generator(7), dtype=torch.float64).to(dtype)
    ops = [
        SparseViewOperator.from_maps(img_a, maps_a),
        SparseViewOperator.from_maps(img_b, maps_b),
        SparseViewOperator.from_forward_map(img_c, torch.rand(3, H, W, dtype=torch.float64).to(dtype) * W),
    ]
    op = SparseViewOperator.concat(ops)
    assert op.n_views == sum(o.n_views for o in ops)
    assert op.G.shape == (3 * H * W, sum(o.G.shape[1] for o in ops))
    assert op.C.shape == (op.G.shape[1], op.n_views)
    assert op.nnz == (sum(o.nnz[0] for o in ops), sum(o.nnz[1] for o in ops))
    assert op.C.is_coalesced() and torch.equal(op.C.indices(), op.C.coalesce().indices())
    assert_close(op.data_matrix(), torch.cat([o.data_matrix() for o in ops], dim=1), dtype)
    assert_close(op.views(), torch.cat([o.views() for o in ops]), dtype)


def test_fit_sparse_equals_dense_fit(dtype: torch.dtype) -> None:
    ops = [SparseViewOperator.from_maps(*setup(dtype, 3, 2, seed=s)) for s in (8, 9)]
    op = SparseViewOperator.concat(ops)
    sparse_fit = Eigenspace(n_components=3).fit_sparse(op.G, op.C, image_shape=op.image_shape, block_size=5)
    views = torch.cat(
        [NovelViewWarp.apply_maps(m, i[:, None])[0] for i, m in (setup(dtype, 3, 2, seed=s) for s in (8, 9))]
    )
    dense_fit = Eigenspace(n_components=3).fit(views)
    tol = 1e-3 if dtype == torch.float32 else 1e-9
    u, v = sparse_fit.components_, dense_fit.components_
    sign = torch.sign((u * v).sum(dim=1, keepdim=True))
    torch.testing.assert_close(u, v * sign, rtol=0, atol=tol)
    torch.testing.assert_close(sparse_fit.mean_, dense_fit.mean_, rtol=0, atol=tol)
    torch.testing.assert_close(sparse_fit.eigenvalues_, dense_fit.eigenvalues_, rtol=tol, atol=tol)


# --------------------------------------------------------------------------- errors and repr
def test_repr_and_nnz() -> None:
    op = SparseViewOperator.from_maps(*setup(torch.float64, 1, 2))
    text = repr(op)
    assert text.startswith("SparseViewOperator(image_shape=(1, 12, 16), n_views=7")
    assert f"nnz={op.nnz[0]}" in text and f"nnz={op.nnz[1]}" in text
    assert op.nnz[1] <= 2 * 2 * len(THETAS) * H * W


def test_from_maps_errors() -> None:
    images, maps = setup(torch.float64, 3, 2)
    two = dataclasses.replace(
        maps, src_x=maps.src_x.expand(2, 2, -1, -1, -1), weight=maps.weight.expand(2, 2, -1, -1, -1)
    )
    with pytest.raises(ValueError, match=r"one object \(B = 1\), got B=2"):
        SparseViewOperator.from_maps(images, two)
    with pytest.raises(
        ValueError, match=r"images are \(H, W\)=\(12, 15\), the maps were built for \(H, W\)=\(12, 16\)"
    ):
        SparseViewOperator.from_maps(images[..., :-1], maps)
    with pytest.raises(
        ValueError,
        match=r"images are \(H, W\)=\(6, 8\), the maps were built for \(H, W\)=\(12, 16\).*these images$",
    ):
        SparseViewOperator.from_maps(images[..., ::2, ::2], maps)  # smaller images: not blamed on support=
    with pytest.raises(ValueError, match=r"images are \(H, W\)=\(24, 16\).*or the maps hold a band of rows"):
        SparseViewOperator.from_maps(torch.cat([images, images], dim=2), maps)
    with pytest.raises(ValueError, match=r"images must have shape \(S, C, H, W\) = \(2, C, 12, 16\)"):
        SparseViewOperator.from_maps(images[:1], maps)
    with pytest.raises(ValueError, match="images must have shape"):
        SparseViewOperator.from_maps(images[0], maps)
    with pytest.raises(ValueError, match=r"mode must be one of .*'bilinear'"):
        SparseViewOperator.from_maps(images, maps, mode="bilinear")
    with pytest.raises(ValueError, match="use from_forward_map"):
        SparseViewOperator.from_maps(images, maps, mode="splat")
    with pytest.raises(TypeError, match=r"images must have a floating dtype, got torch\.uint8"):
        SparseViewOperator.from_maps((images * 255).to(torch.uint8), maps)
    with pytest.raises(TypeError, match="maps must be a WarpMaps"):
        SparseViewOperator.from_maps(images, maps.src_x)  # type: ignore[arg-type]
    bad = maps.src_x.clone()
    bad[0, 0, 0, 0, 0] = math.nan
    with pytest.raises(ValueError, match=r"maps.src_x \(where maps.weight is non-zero\) must be finite"):
        SparseViewOperator.from_maps(images, dataclasses.replace(maps, src_x=bad))
    with pytest.raises(ValueError, match=r"maps\.weight must have the shape of maps\.src_x"):
        SparseViewOperator.from_maps(images, dataclasses.replace(maps, weight=maps.weight[..., :-1]))


def test_from_maps_row_layout_needs_rows_that_stay() -> None:
    images, maps = setup(torch.float64, 1, 2)
    own_row = torch.arange(H, dtype=torch.float64).view(1, 1, 1, H, 1).expand_as(maps.src_x)
    same = SparseViewOperator.from_maps(images, dataclasses.replace(maps, src_y=own_row.clone()))
    assert same.layout == "row"
    assert torch.equal(same.views(), SparseViewOperator.from_maps(images, maps).views())
    moved = own_row.clone()
    moved[tuple((maps.weight != 0).nonzero()[-1])] += 0.5
    moved_maps = dataclasses.replace(maps, src_y=moved)
    with pytest.raises(
        ValueError, match=r"layout='row' needs maps\.src_y None or each target pixel's own row"
    ):
        SparseViewOperator.from_maps(images, moved_maps, layout="row")
    assert SparseViewOperator.from_maps(images, moved_maps).layout == "image"
    with pytest.raises(ValueError, match=r"layout must be 'auto' or one of"):
        SparseViewOperator.from_maps(images, maps, layout="rows")


@pytest.mark.parametrize("n_sources", [1, 2])
@pytest.mark.parametrize("channels", [1, 3])
def test_image_layout_equals_kornia_2d_warp(dtype: torch.dtype, channels: int, n_sources: int) -> None:
    """Sec. 4: whole-image coefficient vectors give exactly the 2D-warped views."""
    gen = generator(5)
    images = torch.rand(n_sources, channels, H, W, generator=gen, dtype=torch.float64).to(dtype)
    images[0, :, 3] = 0.0  # zeros are not stored in G
    maps = maps_2d(dtype, n_sources)
    expected = NovelViewWarp.apply_maps(maps, images[:, None])[0]
    op = SparseViewOperator.from_maps(images, maps)
    n = H * W
    assert op.layout == "image"
    assert op.G.shape == (channels * n, n_sources * n * n) and op.C.shape == (n_sources * n * n, len(THETAS))
    assert op.G.is_coalesced() and op.C.is_coalesced()
    # At most four bilinear weights per target pixel, source and view.
    assert op.nnz[1] <= 4 * n * n_sources * len(THETAS)
    assert_close(op.views(), expected, dtype)


def test_image_layout_matches_a_dense_g() -> None:
    """The stored G (only the columns C uses) gives the product of the full G of Sec. 4."""
    gen = generator(2)
    h, w = 4, 5
    n = h * w
    images = torch.rand(2, 1, h, w, generator=gen, dtype=torch.float64)
    yy = torch.arange(h, dtype=torch.float64).view(h, 1).expand(h, w)
    xx = torch.arange(w, dtype=torch.float64).view(1, w).expand(h, w)
    src_x = (xx * 0.8 + 0.6 + 0.3 * yy).expand(2, 1, 3, h, w).clone()
    src_y = (yy * 0.9 + 0.2 * xx).expand(2, 1, 3, h, w).clone()
    weight = torch.full_like(src_x, 0.5)
    op = SparseViewOperator.from_maps(images, WarpMaps(src_x, weight, weight > 0, torch.zeros(3), src_y))
    full_g = torch.zeros(n, 2 * n * n, dtype=torch.float64)
    for p in range(n):
        for s in range(2):
            full_g[p, s * n * n + p * n : s * n * n + (p + 1) * n] = images[s, 0].reshape(-1)
    stored = op.G.to_dense()
    assert torch.equal(stored[stored != 0], full_g[stored != 0])  # a sub-pattern of the full G
    torch.testing.assert_close(full_g @ op.C.to_dense(), op.data_matrix(), rtol=0, atol=1e-14)
    # A target pixel's weights sum to its blend weights (1) where its source lies inside.
    per_target = op.C.to_dense().view(2, n, n, 3).sum(dim=(0, 2))
    inside = ((src_x[0, 0] <= w - 1) & (src_y[0, 0] <= h - 1)).reshape(3, n).T
    assert 0 < int(inside.sum()) < inside.numel()
    torch.testing.assert_close(per_target[inside], torch.ones_like(per_target[inside]), rtol=0, atol=1e-12)
    assert bool((per_target[~inside] < 1 - 1e-6).all())


def test_from_forward_map_errors() -> None:
    image = torch.rand(3, 5, 7, dtype=torch.float64)
    x3 = torch.rand(2, 5, 7, dtype=torch.float64)
    with pytest.raises(ValueError, match=r"dst_x_for_src must have shape \(T, H, W\) = \(T, 5, 7\)"):
        SparseViewOperator.from_forward_map(image, x3[..., :-1])
    with pytest.raises(ValueError, match=r"image must have shape \(C, H, W\)"):
        SparseViewOperator.from_forward_map(image[None], x3)
    with pytest.raises(TypeError, match="image must have a floating dtype"):
        SparseViewOperator.from_forward_map(image.long(), x3)
    with pytest.raises(TypeError, match="dst_x_for_src must have a floating dtype"):
        SparseViewOperator.from_forward_map(image, x3.long())
    inf = x3.clone()
    inf[0, 0, 0] = math.inf
    with pytest.raises(ValueError, match=r"dst_x_for_src .* must be finite"):
        SparseViewOperator.from_forward_map(image, inf)


def test_concat_errors() -> None:
    op = SparseViewOperator.from_maps(*setup(torch.float64, 3, 1))
    other = SparseViewOperator.from_maps(*setup(torch.float64, 1, 1))
    with pytest.raises(ValueError, match="non-empty sequence"):
        SparseViewOperator.concat([])
    with pytest.raises(
        TypeError, match="ops must be a sequence of SparseViewOperator, got SparseViewOperator"
    ):
        SparseViewOperator.concat(op)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"ops\[1\].image_shape=\(1, 12, 16\) must equal"):
        SparseViewOperator.concat([op, other])
    with pytest.raises(TypeError, match=r"ops\[1\] must be a SparseViewOperator"):
        SparseViewOperator.concat([op, op.G])  # type: ignore[list-item]
    op32 = SparseViewOperator.from_maps(*setup(torch.float32, 3, 1))
    with pytest.raises(TypeError, match=r"ops\[1\] has dtype torch.float32"):
        SparseViewOperator.concat([op, op32])


@pytest.mark.slow
def test_matches_kornia_at_coil_size_float32() -> None:
    """The issue's bar at a real image size: G·C and remap agree to 1e-5 in float32."""
    gen = torch.Generator().manual_seed(0)
    h = w = 128
    images = torch.rand(2, 1, h, w, generator=gen)
    disparity = torch.nn.functional.avg_pool2d(torch.randn(1, 1, h, w, generator=gen) * 20, 15, 1, 7)[0]
    corr = correspondence_from_disparity(disparity, -disparity)
    warp = NovelViewWarp(10.0)
    maps = warp.maps(corr, list(range(-20, 21, 5)))
    expected = warp.apply_maps(maps, images[:, None])[0]
    actual = SparseViewOperator.from_maps(images, maps).views()
    assert float((actual - expected).abs().max()) <= 1e-5
