"""Semi-global matching's aggregation and winner against plain-Python references."""

from __future__ import annotations

import torch

from torch_eigview.geometry.sgm import aggregate, winner


def _path_costs(cost: torch.Tensor, dy: int, dx: int, p1: float, p2: float) -> torch.Tensor:
    """Hirschmüller's L_r for one direction r = (dy, dx), pixel by pixel, (L, H, W) float64."""
    n_labels, h, w = cost.shape
    out = torch.zeros_like(cost, dtype=torch.float64)
    ys = range(h) if dy >= 0 else range(h - 1, -1, -1)
    xs = range(w) if dx >= 0 else range(w - 1, -1, -1)
    for y in ys:
        for x in xs:
            py, px = y - dy, x - dx
            if not (0 <= py < h and 0 <= px < w):
                out[:, y, x] = cost[:, y, x]
                continue
            prev = out[:, py, px]
            low = float(prev.min())
            for k in range(n_labels):
                cands = [float(prev[k]), low + p2]
                if k > 0:
                    cands.append(float(prev[k - 1]) + p1)
                if k < n_labels - 1:
                    cands.append(float(prev[k + 1]) + p1)
                out[k, y, x] = float(cost[k, y, x]) + min(cands) - low
    return out


def test_aggregate_matches_the_four_path_reference() -> None:
    gen = torch.Generator().manual_seed(3)
    cost = torch.rand(2, 5, 4, 6, generator=gen, dtype=torch.float64)
    p1, p2 = 0.05, 0.3
    got = aggregate(cost, p1, p2)
    for i in range(2):
        ref = sum(_path_costs(cost[i], dy, dx, p1, p2) for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)))
        torch.testing.assert_close(got[i], ref, atol=1e-12, rtol=0)


def test_winner_takes_the_first_least_cost_with_a_parabola() -> None:
    """Ties go to the first label (as ``argmin``), an inner minimum gets the parabola's
    sub-label offset (within ±0.5), a minimum at the ends none; labels are centred."""
    volume = torch.tensor([[3.0, 1.0, 1.0, 4.0, 5.0], [2.0, 1.0, 2.0, 3.0, 4.0], [0.0, 1.0, 2.0, 3.0, 4.0]])
    volume = volume.T.reshape(1, 5, 1, 3)  # (N, L, H, W): three pixels of one row
    got = winner(volume)[0, 0]
    # Pixel 0: labels 1 and 2 tie at 1 -> label 1, parabola through 3, 1, 1: offset +0.5.
    # Pixel 1: label 1, symmetric neighbours: offset 0. Pixel 2: label 0 at the end: no offset.
    torch.testing.assert_close(got, torch.tensor([1.5 - 2, 1.0 - 2, 0.0 - 2]))
    flat = torch.ones(1, 4, 2, 2)
    assert torch.equal(winner(flat), torch.full((1, 2, 2), -1.0))  # all tie: the first label, centred
