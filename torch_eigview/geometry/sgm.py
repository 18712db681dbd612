"""Semi-global matching's aggregation (Hirschmüller) over a cost volume, and the winner.

Convention: a cost volume is (N, L, H, W), the cost of label k in [0, L) at each pixel of
N images; labels are ordered so that neighbouring labels are neighbouring depths, which
SGM's P1 (one label) and P2 (any larger jump) penalties assume.
"""

from __future__ import annotations

import torch

__all__ = ["aggregate", "winner"]


def aggregate(cost: torch.Tensor, p1: float, p2: float) -> torch.Tensor:
    """SGM: (N, L, H, W) costs summed over the four row and column paths.

    Each path is scanned on a layout whose scanned axis is the second-to-last (the rows'
    paths on one transposed copy of the volume) and adds each step's costs straight into
    the sum, in the fixed order left-to-right, right-to-left, top-down, bottom-up: no
    volume per path.
    """
    across = cost.transpose(-1, -2).contiguous()  # (N, L, W, H): a row path scans axis -2
    acc = torch.zeros_like(across)
    _scan(across, acc, False, p1, p2)
    _scan(across, acc, True, p1, p2)
    total = acc.transpose(-1, -2).contiguous()
    del acc, across
    _scan(cost, total, False, p1, p2)
    _scan(cost, total, True, p1, p2)
    return total


def _scan(c: torch.Tensor, acc: torch.Tensor, reverse: bool, p1: float, p2: float) -> None:
    """Adds one SGM path along axis -2 of ``c`` (N, L, S, X) to ``acc`` (same shape):
    L_r(p, k) = C(p, k) + min(L_r(p − r, k), L_r(p − r, k ± 1) + P1,
    min_j L_r(p − r, j) + P2) − min_j L_r(p − r, j)."""
    n, n_labels, s, x = c.shape
    order = range(s - 1, -1, -1) if reverse else range(s)
    # The previous step's costs between two +inf labels: its label neighbours k ± 1 are
    # slices of one buffer, and each step writes in place (no per-step allocations). The
    # penalties are 0-dim tensors of the volume's dtype, converted once rather than on every
    # call as a Python number would be (the same sums), and the positions' slices are taken
    # once.
    padded = torch.full((n, n_labels + 2, x), float("inf"), dtype=c.dtype, device=c.device)
    prev = padded[:, 1:-1]
    low = torch.empty_like(prev[:, :1])
    jump = torch.empty_like(low)
    step = torch.empty_like(prev)
    pen1, pen2 = (torch.tensor(p, dtype=c.dtype, device=c.device) for p in (p1, p2))
    costs, sums = c.unbind(2), acc.unbind(2)
    prev.copy_(costs[order[0]])
    sums[order[0]].add_(prev)
    for t in order[1:]:
        torch.amin(prev, dim=1, keepdim=True, out=low)
        torch.minimum(padded[:, 2:], padded[:, :-2], out=step)
        step.add_(pen1)
        torch.minimum(step, prev, out=step)
        torch.minimum(step, torch.add(low, pen2, out=jump), out=step)
        torch.add(costs[t], step, out=prev)
        prev.sub_(low)
        sums[t].add_(prev)


def winner(volume: torch.Tensor) -> torch.Tensor:
    """(N, H, W) sub-pixel label (centred: 0 is the middle label) of least cost."""
    n_labels = volume.shape[1]
    c0, k = volume.min(dim=1, keepdim=True)  # the first least cost, as argmin gives, and its value
    cm = volume.gather(1, (k - 1).clamp(min=0))
    cp = volume.gather(1, (k + 1).clamp(max=n_labels - 1))
    curv = cm - 2 * c0 + cp
    inner = (k > 0) & (k < n_labels - 1) & (curv > 0)
    delta = torch.where(inner, (cm - cp) / (2 * curv).clamp_min(1e-12), torch.zeros_like(c0))
    return (k + delta.clamp(-0.5, 0.5) - (n_labels - 1) // 2)[:, 0].to(volume.dtype)
