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

    The paths of one length run as one batch (both directions of the rows, and the
    columns too when H = W): one scan of fewer, larger steps.
    """
    paths = [(dim, reverse) for dim in (-1, -2) for reverse in (False, True)]
    groups: dict[int, list[tuple[int, bool]]] = {}
    for dim, reverse in paths:
        groups.setdefault(cost.shape[dim], []).append((dim, reverse))
    n = cost.shape[0]
    results = {}
    for group in groups.values():
        starts = [cost.movedim(dim, 0) for dim, _ in group]
        stacked = torch.cat(
            [c.flip(0) if rev else c for c, (_, rev) in zip(starts, group, strict=True)], dim=1
        )
        scanned = _path(stacked, p1, p2)
        for i, (dim, reverse) in enumerate(group):
            part = scanned[:, i * n : (i + 1) * n]
            results[dim, reverse] = (part.flip(0) if reverse else part).movedim(0, dim)
    total = torch.zeros_like(cost)
    for key in paths:  # summed in a fixed order: the same total however they were batched
        total += results[key]
    return total


def _path(c: torch.Tensor, p1: float, p2: float) -> torch.Tensor:
    """SGM paths along the first axis of ``c`` (T, N, L, X): L_r(p, k) = C(p, k) +
    min(L_r(p − r, k), L_r(p − r, k ± 1) + P1, min_j L_r(p − r, j) + P2) − min_j L_r(p − r, j)."""
    out = torch.empty_like(c)
    out[0] = c[0]
    # The previous step's costs between two +inf labels: its label neighbours k ± 1 are
    # slices of one buffer, and each step writes in place (no per-step allocations).
    padded = torch.full(
        (c.shape[1], c.shape[2] + 2, *c.shape[3:]), float("inf"), dtype=c.dtype, device=c.device
    )
    prev = padded[:, 1:-1]
    prev.copy_(c[0])
    low = torch.empty_like(prev[:, :1])
    step = torch.empty_like(prev)
    for t in range(1, c.shape[0]):
        torch.amin(prev, dim=1, keepdim=True, out=low)
        torch.minimum(padded[:, 2:], padded[:, :-2], out=step)
        step.add_(p1)
        torch.minimum(step, prev, out=step)
        torch.minimum(step, low + p2, out=step)
        torch.add(c[t], step, out=prev)
        prev.sub_(low)
        out[t] = prev
    return out


def winner(volume: torch.Tensor) -> torch.Tensor:
    """(N, H, W) sub-pixel label (centred: 0 is the middle label) of least cost."""
    n_labels = volume.shape[1]
    k = volume.argmin(dim=1, keepdim=True)
    c0 = volume.gather(1, k)
    cm = volume.gather(1, (k - 1).clamp(min=0))
    cp = volume.gather(1, (k + 1).clamp(max=n_labels - 1))
    curv = cm - 2 * c0 + cp
    inner = (k > 0) & (k < n_labels - 1) & (curv > 0)
    delta = torch.where(inner, (cm - cp) / (2 * curv).clamp_min(1e-12), torch.zeros_like(c0))
    return (k + delta.clamp(-0.5, 0.5) - (n_labels - 1) // 2)[:, 0].to(volume.dtype)
