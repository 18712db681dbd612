"""Eq. 2 backwards: a view's angle from its points' columns in two seeds and in it
(``fit_view_angle``), and the chaining of two correspondences (``chain_columns``)."""

from __future__ import annotations

import math

import pytest
import torch

from torch_eigview.geometry import Correspondence
from torch_eigview.geometry.view_pose import MIN_POINTS, chain_columns, fit_view_angle


def _points(thetas: list[float], alpha: float, n: int = 400, seed: int = 0) -> tuple[torch.Tensor, ...]:
    """Columns of n random points (X, Z about an axis at column 40) in seeds at 0 and
    ``alpha`` and in views at ``thetas``, each view with its own scale and shift (an image
    normalized to its box keeps Eq. 2 up to an affine map of the view's columns)."""
    g = torch.Generator().manual_seed(seed)
    x, z = torch.rand(2, n, generator=g, dtype=torch.float64) * 40 - 20
    c = 40.0

    def at(deg: float) -> torch.Tensor:
        t = math.radians(deg)
        return c + x * math.cos(t) + z * math.sin(t)

    x1, x2 = at(0.0).expand(len(thetas), n), at(alpha).expand(len(thetas), n)
    x3 = torch.stack([1.2 * at(t) + 3.0 for t in thetas])  # a per-view scale cancels in the angle
    return x1, x2, x3.contiguous()


@pytest.mark.parametrize("alpha", [10.0, 45.0, -30.0])
def test_exact_points_give_the_angle(alpha: float) -> None:
    """Points that follow Eq. 2 give the view's angle, inside the sector and beyond it."""
    thetas = [0.0, alpha / 3, alpha / 2, alpha, -alpha / 4, 1.25 * alpha]
    x1, x2, x3 = _points(thetas, alpha)
    got = fit_view_angle(x1, x2, x3, torch.ones_like(x1, dtype=torch.bool), alpha)
    assert got.dtype == torch.float64
    torch.testing.assert_close(got, torch.tensor(thetas, dtype=torch.float64), atol=1e-6, rtol=0)


def test_where_the_points_lie_does_not_matter() -> None:
    """The same points far from column 0 (a wide image) give the same angles: the fit and
    its degeneracy test work on centred columns."""
    x1, x2, x3 = _points([5.0, 20.0], 45.0)
    use = torch.ones_like(x1, dtype=torch.bool)
    near = fit_view_angle(x1, x2, x3, use, 45.0)
    far = fit_view_angle(x1 + 2000, x2 + 2000, x3 + 1.2 * 2000, use, 45.0)
    torch.testing.assert_close(far, near, atol=1e-9, rtol=0)
    torch.testing.assert_close(near, torch.tensor([5.0, 20.0], dtype=torch.float64), atol=1e-6, rtol=0)


def test_mismatches_count_little() -> None:
    """A fifth of the points matched to random columns moves the angle by well under a degree
    (reweighted least squares), where plain least squares would be far off."""
    thetas = [7.0, 22.0, 38.0]
    x1, x2, x3 = _points(thetas, 45.0)
    g = torch.Generator().manual_seed(1)
    bad = torch.rand(x3.shape, generator=g) < 0.2
    x3 = torch.where(bad, torch.rand(x3.shape, generator=g, dtype=torch.float64) * 80, x3)
    got = fit_view_angle(x1, x2, x3, torch.ones_like(bad), 45.0)
    assert (got - torch.tensor(thetas, dtype=torch.float64)).abs().max() < 0.5


def test_points_left_out_and_too_few() -> None:
    """Points outside ``use`` do not count (here: wild ones), non-finite columns neither, and
    a view with fewer than MIN_POINTS points, or with every point on one column, gives NaN,
    never a guess; MIN_POINTS points are enough."""
    x1, x2, x3 = _points([12.0, 12.0, 12.0], 30.0)
    use = torch.ones_like(x1, dtype=torch.bool)
    x3 = x3.clone()
    x3[0, :50] = 1e4
    use[0, :50] = False
    use[1, MIN_POINTS - 1 :] = False
    flat = torch.full_like(x1, 25.0)
    x3[2] = 25.0
    got = fit_view_angle(
        torch.stack([x1[0], x1[1], flat[2]]), torch.stack([x2[0], x2[1], flat[2]]), x3, use, 30.0
    )
    assert abs(float(got[0]) - 12.0) < 1e-6
    assert math.isnan(float(got[1])) and math.isnan(float(got[2]))
    x1, x2, x3 = _points([12.0], 30.0, n=MIN_POINTS + 1)
    x3[0, 0] = math.nan
    got = fit_view_angle(x1, x2, x3, torch.ones_like(x1, dtype=torch.bool), 30.0)
    assert abs(float(got[0]) - 12.0) < 1e-6
    short = fit_view_angle(x1[:, :5], x2[:, :5], x3[:, :5], torch.ones(1, 5, dtype=torch.bool), 30.0)
    assert math.isnan(float(short[0]))


def test_bad_arguments_are_named() -> None:
    x = torch.zeros(2, 40)
    use = torch.ones(2, 40, dtype=torch.bool)
    with pytest.raises(ValueError, match="one shape"):
        fit_view_angle(x, x, torch.zeros(2, 41), use, 10.0)
    with pytest.raises(ValueError, match=r"x1 must have shape \(N, P\)"):
        fit_view_angle(torch.zeros(40), x, x, use, 10.0)
    with pytest.raises(TypeError, match="use must be a bool tensor"):
        fit_view_angle(x, x, x, use.float(), 10.0)
    with pytest.raises(TypeError, match="x2"):
        fit_view_angle(x, x.long(), x, use, 10.0)
    with pytest.raises(ValueError, match="alpha"):
        fit_view_angle(x, x, x, use, 180.0)


def test_prior_weights() -> None:
    """Uniform weights change nothing; weights that favour the well-measured points move
    the angle onto them (half the points shifted by a bias the Huber weights cannot tell
    from the truth); a point of weight 0 is left out, so too few weighted points give NaN;
    a bad weight is named."""
    thetas = [8.0, 30.0]
    x1, x2, x3 = _points(thetas, 45.0)
    use = torch.ones_like(x1, dtype=torch.bool)
    plain = fit_view_angle(x1, x2, x3, use, 45.0)
    torch.testing.assert_close(fit_view_angle(x1, x2, x3, use, 45.0, weight=torch.full((400,), 3.0)), plain)
    # Any scale of the weights: the same angles (no overflow or underflow in the sums).
    w = torch.rand(400, generator=torch.Generator().manual_seed(2), dtype=torch.float64) + 0.1
    for scale in (1e-200, 1.0, 1e150):
        torch.testing.assert_close(fit_view_angle(x1, x2, x3, use, 45.0, weight=w * scale), plain)
    # Half the points biased towards seed 1 (x3 pulled 30 % of the way back to x1).
    biased = torch.arange(400) % 2 == 0
    x3b = torch.where(biased, x3 + 0.3 * (1.2 * x1 + 3.0 - x3), x3)
    unweighted = fit_view_angle(x1, x2, x3b, use, 45.0)
    weighted = fit_view_angle(x1, x2, x3b, use, 45.0, weight=(~biased).double() * 5 + biased.double() * 0.01)
    truth = torch.tensor(thetas, dtype=torch.float64)
    assert ((weighted - truth).abs() < (unweighted - truth).abs()).all()
    assert (weighted - truth).abs().max() < 0.3
    few = torch.zeros(400)
    few[: MIN_POINTS - 1] = 1.0
    assert fit_view_angle(x1, x2, x3, use, 45.0, weight=few).isnan().all()
    with pytest.raises(ValueError, match=r"weight must have shape \(2, 400\) or \(400,\), got \(399,\)"):
        fit_view_angle(x1, x2, x3, use, 45.0, weight=torch.ones(399))
    with pytest.raises(ValueError, match="weight must be finite and non-negative"):
        fit_view_angle(x1, x2, x3, use, 45.0, weight=-torch.ones(400))
    with pytest.raises(ValueError, match="weight must be finite and non-negative"):
        fit_view_angle(x1, x2, x3, use, 45.0, weight=torch.full((2, 400), math.nan))
    with pytest.raises(TypeError, match="weight"):
        fit_view_angle(x1, x2, x3, use, 45.0, weight=torch.ones(400, dtype=torch.int64))


def _corr(
    disparity: torch.Tensor, valid: torch.Tensor, vertical: torch.Tensor | None = None
) -> Correspondence:
    return Correspondence(disparity, -disparity, valid, valid, vertical, None)


def test_chain_columns_follows_both_correspondences() -> None:
    """x3 = x1 + d13 (moved down the rows by the vertical flow), x2 = x3 + d32 read there;
    a point counts where seed 1 is foreground, the first match is trusted and the second
    is trusted at all four neighbours of where it lands."""
    n, h, w = 2, 6, 10
    d13 = torch.full((n, h, w), 2.5)
    v13 = torch.full((n, h, w), 0.5)
    cols = torch.arange(w, dtype=torch.float32)
    d32 = (0.5 * cols).expand(n, h, w).contiguous()  # read where the point lands: x3
    valid13 = torch.ones(n, h, w, dtype=torch.bool)
    valid13[1, 0, 0] = False
    valid32 = torch.ones(n, h, w, dtype=torch.bool)
    valid32[0, 3, 5] = False  # untrusts the points that land next to (row 3, column 5)
    fg = torch.ones(h, w, dtype=torch.bool)
    fg[:, -1] = False
    x1, x2, x3, use = chain_columns(_corr(d13, valid13, v13), _corr(d32, valid32), fg)
    assert x1.shape == x2.shape == x3.shape == use.shape == (n, h * w)
    torch.testing.assert_close(x3, (cols + 2.5).expand(n, h, w).reshape(n, -1))
    # d32 is read at x3 (border padding past the last column).
    torch.testing.assert_close(x2, x3 + 0.5 * x3.clamp(max=w - 1))
    use = use.view(n, h, w)
    assert not bool(use[..., -1].any())  # not foreground
    assert not bool(use[1, 0, 0])  # first match untrusted
    # Points land half a row down and 2.5 columns right: those from rows 2, 3 and
    # columns 2, 3 of seed 1 have (3, 5) of view 0 among their four neighbours.
    assert not bool(use[0, 2:4, 2:4].any())
    # Landing inside the view: rows up to h - 1.5 (moved down half a row), columns up to
    # w - 3.5 (moved right 2.5); the last column is not foreground anyway.
    assert not bool(use[:, -1].any()) and not bool(use[:, :, w - 3 :].any())
    assert int(use[0].sum()) == (h - 1) * (w - 3) - 4
    assert bool(use[1, 2:4, 2:4].all())


def test_chain_columns_checks_its_arguments() -> None:
    c = _corr(torch.zeros(1, 4, 5), torch.ones(1, 4, 5, dtype=torch.bool))
    with pytest.raises(TypeError, match="to_seed2 must be a Correspondence"):
        chain_columns(c, None, torch.ones(4, 5, dtype=torch.bool))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="one shape"):
        chain_columns(
            c,
            _corr(torch.zeros(1, 4, 6), torch.ones(1, 4, 6, dtype=torch.bool)),
            torch.ones(4, 5, dtype=torch.bool),
        )
    with pytest.raises(TypeError, match="foreground must be a bool tensor"):
        chain_columns(c, c, torch.ones(4, 5))
    with pytest.raises(ValueError, match="foreground must have shape"):
        chain_columns(c, c, torch.ones(5, 4, dtype=torch.bool))
