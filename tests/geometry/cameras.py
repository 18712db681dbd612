"""Cameras on the turntable's circle and the helpers the trifocal tests share."""

from __future__ import annotations

import math

import torch

DT = torch.float64
ALPHA = 10.0
THETAS = [-20.0, 5.0, 25.0, 40.0]
LINES = ["perpendicular", "vertical", "paper"]
# 128x128 images, f = 0.45 * 128 * 4 as synthetic.PerspectiveCamera's default.
K = torch.tensor([[230.4, 0.0, 63.5], [0.0, 230.4, 63.5], [0.0, 0.0, 1.0]], dtype=DT)
DISTANCE = 4.0


def pose(phi: float) -> tuple[torch.Tensor, torch.Tensor]:
    """World to camera of a camera at DISTANCE on a horizontal circle, looking at the origin.

    The object turns by ``phi`` about Y (x = X cos + Z sin), then camera coordinates are
    (x, -y, DISTANCE - z): x right, y down, z forward.
    """
    c, s = math.cos(math.radians(phi)), math.sin(math.radians(phi))
    ry = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], dtype=DT)
    flip = torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=DT))
    return flip @ ry, torch.tensor([0.0, 0.0, DISTANCE], dtype=DT)


def camera(phi: float) -> torch.Tensor:
    r, t = pose(phi)
    return K @ torch.cat([r, t[:, None]], dim=1)


def project(P: torch.Tensor, X: torch.Tensor) -> torch.Tensor:
    x = homogeneous(X) @ P.T
    return x[:, :2] / x[:, 2:]


def homogeneous(p: torch.Tensor) -> torch.Tensor:
    return torch.cat([p, torch.ones_like(p[:, :1])], dim=1)


def skew(v: torch.Tensor) -> torch.Tensor:
    return torch.tensor([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]], dtype=DT)


def rotation(axis: list[float], degrees: float) -> torch.Tensor:
    n = torch.tensor(axis, dtype=DT)
    n = n / n.norm()
    w = skew(n)
    a = math.radians(degrees)
    return torch.eye(3, dtype=DT) + math.sin(a) * w + (1 - math.cos(a)) * w @ w


def same_up_to_scale(a: torch.Tensor, b: torch.Tensor) -> float:
    a, b = a / a.norm(), b / b.norm()
    return min(float((a - b).abs().max()), float((a + b).abs().max()))


def scene_points() -> torch.Tensor:
    """(40, 3) points in a unit cube, |Y| >= 0.2: away from the horizon row (degenerate for "paper")."""
    g = torch.Generator().manual_seed(0)
    X = 2 * torch.rand(40, 3, generator=g, dtype=DT) - 1
    X[:, 1] = torch.sign(X[:, 1]) * (0.2 + 0.8 * X[:, 1].abs())
    return X
