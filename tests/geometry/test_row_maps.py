"""Row-map inversion and hole filling against loops written as their docstrings say."""

from __future__ import annotations

import itertools
import math

import pytest
import torch

from torch_eigview.geometry.row_maps import fill_row_holes, invert_row_map, invert_row_segments

from tests.helpers import rand


def _invert_row_map_loop(
    dst: torch.Tensor, valid: torch.Tensor, depth: torch.Tensor | None, max_stretch: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """invert_row_map written as the docstring says, one segment and one column at a time."""
    b, t, h, w = dst.shape
    out = torch.full_like(dst, math.nan)
    best: dict[tuple[int, int, int, int], tuple[float, float]] = {}
    for i in range(b):
        for j in range(t):
            for r in range(h):
                f = dst[i, j, r].tolist()
                v = (valid[i] if valid.ndim == 3 else valid[i, j])[r].tolist()
                d = None if depth is None else depth[i, j, r].tolist()
                for k in range(w - 1):
                    length = f[k + 1] - f[k]
                    if not (v[k] and v[k + 1] and 0 < length <= max_stretch):
                        continue
                    ends = f[k : k + 2] + ([] if d is None else d[k : k + 2])
                    if not all(math.isfinite(e) for e in ends):
                        continue  # a non-finite end (map or depth): no surface
                    for col in range(w):
                        if not f[k] <= col <= f[k + 1]:
                            continue
                        frac = (col - f[k]) / length
                        src = k + frac
                        if depth is None:
                            key = src
                        else:
                            d0, d1 = float(depth[i, j, r, k]), float(depth[i, j, r, k + 1])
                            key = d0 + (d1 - d0) * frac
                        best[i, j, r, col] = max(best.get((i, j, r, col), (-math.inf, -math.inf)), (key, src))
    hit = torch.zeros(dst.shape, dtype=torch.bool)
    for idx, (_, src) in best.items():
        out[idx] = src
        hit[idx] = True
    return out, hit


def _check_inverse(
    dst: torch.Tensor, valid: torch.Tensor, depth: torch.Tensor | None, stretch: float
) -> None:
    src, hit = invert_row_map(dst, valid, depth, stretch)
    ref_src, ref_hit = _invert_row_map_loop(dst, valid, depth, stretch)
    assert torch.equal(hit, ref_hit)
    assert bool(torch.isnan(src[~hit]).all())
    torch.testing.assert_close(src[hit], ref_src[hit], atol=1e-12, rtol=0)


@pytest.mark.parametrize("stretch", [math.inf, 1.5])
def test_invert_row_map_monotone(stretch: float) -> None:
    b, t, h, w = 2, 2, 3, 12
    steps = 0.3 + 1.5 * rand(b, t, h, w, seed=7)  # increasing, some segments longer than 1.5
    dst = steps.cumsum(-1) - 3.0  # starts left of the image, may end right of it
    valid = rand(b, h, w, seed=8) > 0.15
    _check_inverse(dst, valid, None, stretch)
    _check_inverse(dst, rand(b, t, h, w, seed=15) > 0.15, None, stretch)  # a mask per angle
    src, hit = invert_row_map(dst, torch.ones_like(valid), None)
    # Where it hits, the inverse is a true inverse of the piecewise-linear forward map.
    cols = torch.arange(w, dtype=torch.float64).expand_as(dst)
    k = src.floor().clamp(max=w - 2).long()
    frac = src - k
    fwd = torch.where(
        hit,
        dst.gather(-1, k.clamp(min=0)) * (1 - frac) + dst.gather(-1, (k + 1).clamp(0, w - 1)) * frac,
        cols,
    )
    torch.testing.assert_close(fwd[hit], cols[hit], atol=1e-12, rtol=0)


@pytest.mark.parametrize("use_depth", [True, False])
@pytest.mark.parametrize("valid_rate", [0.2, 0.9])
def test_invert_row_map_sparse_and_dense_segments(use_depth: bool, valid_rate: float) -> None:
    """Few valid segments (an object on a background: only those are gathered) and many
    (slot 0 on views of the map) both equal the loop; a batch mixing the two regimes
    equals its objects inverted one at a time, bit for bit."""
    b, t, h, w = 3, 2, 3, 12
    x = torch.arange(w, dtype=torch.float64)
    dst = x + 2.4 * torch.sin(0.9 * x + rand(b, t, h, 1, seed=21) * 6)  # folds and long segments
    depth = rand(b, t, h, w, seed=22) if use_depth else None
    valid = rand(b, h, w, seed=23) < valid_rate
    _check_inverse(dst, valid, depth, 2.5)
    valid[0] = True  # object 0 alone takes the other regime than a sparse batch
    src, hit = invert_row_map(dst, valid, depth, 2.5)
    for i in range(b):
        one = invert_row_map(
            dst[i : i + 1], valid[i : i + 1], None if depth is None else depth[i : i + 1], 2.5
        )
        assert torch.equal(one[1], hit[i : i + 1])
        assert torch.equal(one[0][one[1]], src[i : i + 1][hit[i : i + 1]])


@pytest.mark.parametrize("use_depth", [True, False])
@pytest.mark.parametrize("valid_rate", [0.3, 1.0])
def test_invert_row_map_non_finite_ends(use_depth: bool, valid_rate: float) -> None:
    """A segment with an infinite or NaN end, in the map or the depth, is left out: in the
    sparse regime (checked on the gathered ends) as in the dense one (on the whole map)."""
    b, t, h, w = 2, 1, 4, 10
    dst = (0.4 + rand(b, t, h, w, seed=31)).cumsum(-1) - 1.0
    depth = rand(b, t, h, w, seed=32) if use_depth else None
    valid = rand(b, h, w, seed=33) < valid_rate
    valid[:, :, 2:6] = True  # segments that would pass but for their ends
    dst[0, 0, 0, 3], dst[0, 0, 1, 4], dst[1, 0, 2, 5] = math.inf, math.nan, -math.inf
    if depth is not None:
        depth[1, 0, 3, 3], depth[0, 0, 2, 2] = math.inf, math.nan
    for stretch in (math.inf, 2.0):
        _check_inverse(dst, valid, depth, stretch)


@pytest.mark.parametrize("use_depth", [True, False])
def test_invert_row_map_fold_picks_nearest(use_depth: bool) -> None:
    """A map that folds back (x - 2.4 sin x): the reversed segments are dropped and where
    the forward ones overlap, the largest depth (or, without depth, source x) wins."""
    b, t, h, w = 1, 2, 4, 16
    x = torch.arange(w, dtype=torch.float64)
    phase = rand(b, t, h, 1, seed=9) * 6
    dst = x + 2.4 * torch.sin(0.9 * x + phase)
    depth = rand(b, t, h, w, seed=10) if use_depth else None
    valid = torch.ones(b, h, w, dtype=torch.bool)
    _check_inverse(dst, valid, depth, math.inf)
    _check_inverse(dst, valid, depth, 2.0)
    if use_depth:
        # Raising a segment's depth above everything makes it win every column it covers.
        k = 5
        depth2 = depth.clone()
        depth2[..., k : k + 2] = 10.0
        src, _ = invert_row_map(dst, valid, depth2)
        lo, hi = dst[..., k], dst[..., k + 1]
        cols = x.expand_as(dst)
        covered = (cols >= lo[..., None]) & (cols <= hi[..., None]) & (hi > lo)[..., None]
        assert bool(covered.any())
        assert bool(((src[covered] >= k) & (src[covered] <= k + 1)).all())


def test_invert_row_map_max_stretch_is_inclusive() -> None:
    dst = torch.tensor([0.0, 2.0, 4.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0], dtype=torch.float64).expand(
        1, 1, 1, 9
    )
    src, hit = invert_row_map(dst, torch.ones(1, 1, 9, dtype=torch.bool), None, max_stretch=2.0)
    # Segments of length 2 are surface, the 3 px jump from 4 to 7 is not.
    assert hit[0, 0, 0].tolist() == [True, True, True, True, True, False, False, True, True]
    torch.testing.assert_close(src[0, 0, 0, :5], torch.tensor([0.0, 0.5, 1.0, 1.5, 2.0], dtype=torch.float64))
    torch.testing.assert_close(src[0, 0, 0, 7:], torch.tensor([3.0, 4.0], dtype=torch.float64))


def test_invert_row_map_no_segment() -> None:
    dst = torch.arange(6, dtype=torch.float64).flip(-1).expand(1, 1, 2, 6)  # all reversed
    src, hit = invert_row_map(dst, torch.ones(1, 2, 6, dtype=torch.bool), None)
    assert not bool(hit.any()) and bool(torch.isnan(src).all())
    src, hit = invert_row_map(torch.zeros(1, 1, 2, 1), torch.ones(1, 2, 1, dtype=torch.bool), None)
    assert src.shape == (1, 1, 2, 1) and not bool(hit.any())


def _segments_of(
    dst: torch.Tensor, valid: torch.Tensor, depth: torch.Tensor | None
) -> tuple[
    torch.Tensor, torch.Tensor, tuple[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor] | None
]:
    """The arguments of invert_row_segments: every pair of valid neighbours (the order,
    length and finiteness tests left to it), (row, k) in the B·T·H rows, the ends gathered."""
    b, t, h, w = dst.shape
    pairs = valid[..., :-1] & valid[..., 1:]
    row, k = pairs.expand(b, t, h, w - 1).reshape(-1, w - 1).nonzero().unbind(1)

    def at(v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        rows = v.reshape(-1, w)
        return rows[row, k], rows[row, k + 1]

    return row, k, at(dst), None if depth is None else at(depth)


@pytest.mark.parametrize("use_depth", [True, False])
@pytest.mark.parametrize("stretch", [math.inf, 2.5])
@pytest.mark.parametrize("valid_rate", [0.25, 0.9])
def test_invert_row_segments_equals_invert_row_map_bit_for_bit(
    use_depth: bool, stretch: float, valid_rate: float
) -> None:
    """Given the valid pairs alone (their order, length and finiteness tested inside), the
    same inverse as from the whole maps: folds, long segments, non-finite ends, T angles,
    and with a fallback the same filled map."""
    b, t, h, w = 3, 2, 4, 13
    x = torch.arange(w, dtype=torch.float64)
    dst = x + 2.4 * torch.sin(0.9 * x + rand(b, t, h, 1, seed=51) * 6)
    depth = rand(b, t, h, w, seed=52) if use_depth else None
    valid = rand(b, 1, h, w, seed=53) < valid_rate
    dst[0, 1, 2, 4], dst[2, 0, 1, 7] = math.inf, math.nan
    if depth is not None:
        depth[1, 1, 3, 5] = -math.inf
    src, hit = invert_row_map(dst, valid[:, 0], depth, stretch)
    seg_src, seg_hit = invert_row_segments(*_segments_of(dst, valid, depth), (b, t, h, w), stretch)
    assert torch.equal(seg_hit, hit) and bool(hit.any())
    assert torch.equal(seg_src[hit], src[hit]) and bool(torch.isnan(seg_src[~hit]).all())
    fallback = (0.9 * x + 0.4).expand(b, t, h, w)
    filled, _ = invert_row_segments(
        *_segments_of(dst, valid, depth), (b, t, h, w), stretch, fallback=fallback
    )
    assert torch.equal(filled, fill_row_holes(src, hit, fallback))
    assert torch.equal(invert_row_map(dst, valid[:, 0], depth, stretch, fallback=fallback)[0], filled)


def test_invert_row_segments_none_and_errors() -> None:
    empty = torch.zeros(0, dtype=torch.int64)
    ends = (torch.zeros(0), torch.zeros(0))
    src, hit = invert_row_segments(empty, empty, ends, None, (1, 1, 2, 5))
    assert src.shape == (1, 1, 2, 5) and not bool(hit.any()) and bool(torch.isnan(src).all())
    with pytest.raises(ValueError, match=r"one shape \(P,\)"):
        invert_row_segments(empty, torch.zeros(2, dtype=torch.int64), ends, None, (1, 1, 2, 5))
    with pytest.raises(ValueError, match=r"shape must be \(B, T, H, W\)"):
        invert_row_segments(empty, empty, ends, None, (2, 5))  # type: ignore[arg-type]


def _fill_row_holes_loop(src: torch.Tensor, hit: torch.Tensor, fallback: torch.Tensor) -> torch.Tensor:
    out = src.clone()
    w = src.shape[-1]
    for idx in itertools.product(*map(range, src.shape[:-1])):
        hits = [k for k in range(w) if hit[idx][k]]
        for j in range(w):
            if hit[idx][j]:
                continue
            prev = [k for k in hits if k < j]
            nxt = [k for k in hits if k > j]
            s, f = src[idx], fallback[idx]
            if prev and nxt:
                p, n = prev[-1], nxt[0]
                out[idx][j] = s[p] + (s[n] - s[p]) * (j - p) / (n - p)
            elif prev:
                out[idx][j] = f[j] + s[prev[-1]] - f[prev[-1]]
            elif nxt:
                out[idx][j] = f[j] + s[nxt[0]] - f[nxt[0]]
            else:
                out[idx][j] = f[j]
    return out


def test_fill_row_holes() -> None:
    shape = (2, 3, 4, 9)
    hit = rand(*shape, seed=11) < 0.4
    hit[0, 0, 0] = False  # an empty row
    hit[0, 0, 1] = torch.tensor([False, False, True, False, False, True, False, False, False])
    src = torch.where(hit, 10 * rand(*shape, seed=12), torch.full(shape, math.nan, dtype=torch.float64))
    fallback = 3.0 * torch.arange(9, dtype=torch.float64) + rand(*shape, seed=13)
    filled = fill_row_holes(src, hit, fallback)
    assert bool(torch.isfinite(filled).all())  # the NaN of the non-hits never leaks
    torch.testing.assert_close(filled, _fill_row_holes_loop(src, hit, fallback), atol=1e-12, rtol=0)
    assert torch.equal(filled[hit], src[hit])
    assert torch.equal(filled[0, 0, 0], fallback[0, 0, 0])
    row, s, f = filled[0, 0, 1], src[0, 0, 1], fallback[0, 0, 1]
    torch.testing.assert_close(
        row[3:5], s[2] + (s[5] - s[2]) * torch.tensor([1 / 3, 2 / 3], dtype=torch.float64)
    )
    torch.testing.assert_close(row[6:], f[6:] + (s[5] - f[5]))  # beyond the last hit
    torch.testing.assert_close(row[:2], f[:2] + (s[2] - f[2]))  # before the first hit


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fill_row_holes_object_rows(dtype: torch.dtype) -> None:
    """Rows as an object on a background leaves them: a run of hits with gaps inside
    (interpolated), background on both sides (the shifted fallback), rows with a single hit,
    with hits at both borders, all hits, none; any leading shape, NaN off the hits."""
    w = 11
    rows = [
        [0, 0, 1, 1, 0, 0, 1, 1, 1, 0, 0],
        [0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0],
        [1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1],
        [1] * w,
        [0] * w,
        [0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0],
    ]
    hit = torch.tensor(rows, dtype=torch.bool).repeat(2, 2, 1).view(2, 2, 6, w)
    src = torch.where(hit, (12 * rand(2, 2, 6, w, seed=41)).to(dtype), math.nan)
    fallback = (1.1 * torch.arange(w, dtype=dtype) - 0.3)[None, :] * (1 + rand(2, 1, 1, 1, seed=42)).to(dtype)
    filled = fill_row_holes(src, hit, fallback)
    assert filled.dtype == dtype and bool(torch.isfinite(filled).all())
    ref = _fill_row_holes_loop(src.double(), hit, fallback.double().expand_as(src)).to(dtype)
    torch.testing.assert_close(filled, ref, atol=1e-5 if dtype == torch.float32 else 1e-12, rtol=0)
    assert torch.equal(filled[hit], src[hit])
    flat = fill_row_holes(src.reshape(-1, w), hit.reshape(-1, w), fallback.expand_as(src).reshape(-1, w))
    assert torch.equal(flat.view_as(filled), filled)  # rows are independent of their batching


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fill_row_holes_paths_agree_bit_for_bit(dtype: torch.dtype) -> None:
    """Mostly hits and mostly holes give the same values: rows are independent, and rows
    of holes added below a batch change none of its rows (the former code took two paths
    by the share of holes; one remains)."""
    gen = torch.Generator().manual_seed(3)
    src = torch.rand(6, 40, generator=gen, dtype=dtype) * 40
    hit = torch.rand(6, 40, generator=gen) > 0.2
    hit[2] = False  # a row without hits: the fallback
    hit[3, :5] = hit[3, -7:] = False  # holes before the first hit and after the last
    fallback = torch.linspace(-3.0, 41.0, 40, dtype=dtype)
    dense = fill_row_holes(src, hit, fallback)  # mostly hits
    padded = torch.cat([src, torch.zeros(30, 40, dtype=dtype)])
    sparse = fill_row_holes(padded, torch.cat([hit, torch.zeros(30, 40, dtype=torch.bool)]), fallback)
    assert torch.equal(dense, sparse[:6])
    assert torch.equal(dense[hit], src[hit]) and torch.equal(dense[2], fallback)


@pytest.mark.parametrize("hit_rate", [0.3, 0.8])
def test_fill_row_holes_differentiates_strided_inputs(hit_rate: float) -> None:
    """A permuted (non-contiguous) map and mask with a gradient: the values of the
    contiguous call, and gradients that pass gradcheck, for either share of holes."""
    gen = torch.Generator().manual_seed(5)
    hit = (torch.rand(5, 4, 6, generator=gen) < hit_rate).permute(2, 1, 0)
    src = torch.randn(5, 4, 6, generator=gen, dtype=torch.float64).permute(2, 1, 0).requires_grad_()
    fallback = torch.linspace(0.0, 4.0, 5, dtype=torch.float64, requires_grad=True)
    out = fill_row_holes(src, hit, fallback)
    assert torch.equal(out, fill_row_holes(src.detach().contiguous(), hit.contiguous(), fallback.detach()))
    assert torch.autograd.gradcheck(lambda s, f: fill_row_holes(s, hit, f), (src, fallback))
