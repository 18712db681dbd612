"""What the scikit-learn estimators share: NumPy ↔ torch conversion and the bool check."""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["FLOATS", "check_bool", "to_numpy", "to_tensor"]

FLOATS = [np.float64, np.float32]  # kept as they are; any other dtype becomes the first


def to_tensor(x: np.ndarray) -> torch.Tensor:
    """A validated array as a tensor on its memory (a copy when read-only: torch writes nowhere,
    but ``from_numpy`` wants a writable array)."""
    x = np.ascontiguousarray(x)
    return torch.from_numpy(x if x.flags.writeable else x.copy())


def to_numpy(t: torch.Tensor) -> np.ndarray:
    return t.detach().cpu().numpy()


def check_bool(value: object, name: str) -> bool:
    if not isinstance(value, bool):
        raise TypeError(f"{name} must be a bool, got {value!r}")
    return value
