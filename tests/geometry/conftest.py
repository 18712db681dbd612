"""Fixtures of the geometry tests."""

from __future__ import annotations

import pytest
import torch

from tests.geometry.cameras import scene_points


@pytest.fixture(scope="module")
def points() -> torch.Tensor:
    """(40, 3) scene points, away from the horizon row (:func:`~tests.geometry.cameras.scene_points`)."""
    return scene_points()
