"""elevation="auto" when the flow cannot measure it: a warning and the untilted camera,
never the warp's refusal of a saturated ±90 degrees; and SynthesisOptions' argument checks."""

from __future__ import annotations

import math

import pytest
import torch

import torch_eigview.synthesis.seed_pairs as seed_pairs
from torch_eigview.synthesis import (
    MAX_AUTO_ELEVATION,
    ElevationFallbackWarning,
    SynthesisOptions,
    pair_geometry,
    synthesize_views,
)

from tests.helpers import rand

OPTS = SynthesisOptions(flow="ilk")


def test_no_trusted_foreground_falls_back_to_zero() -> None:
    seeds = torch.zeros(2, 1, 8, 10)  # all background: nothing to fit
    with pytest.warns(
        ElevationFallbackWarning, match=r"seed pair 0: .*no trusted correspondence.*elevation=0"
    ):
        (geo,) = pair_geometry(seeds, 10.0, OPTS)
    assert geo.elevation == 0.0


@pytest.mark.parametrize("estimate", [90.0, -90.0, MAX_AUTO_ELEVATION, math.nan])
def test_saturated_fit_falls_back_to_zero(monkeypatch: pytest.MonkeyPatch, estimate: float) -> None:
    monkeypatch.setattr(seed_pairs, "estimate_elevation", lambda *a, **k: torch.tensor([estimate]))
    seeds = rand(2, 1, 8, 10, dtype=torch.float32)
    with pytest.warns(ElevationFallbackWarning, match=r"the fit gave elevation="):
        out = synthesize_views(seeds, 10.0, [0.0, 5.0], OPTS)
    assert out.elevations == [0.0] and bool(torch.isfinite(out.views).all())


def test_plausible_fit_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(seed_pairs, "estimate_elevation", lambda *a, **k: torch.tensor([12.5]))
    (geo,) = pair_geometry(rand(2, 1, 8, 10, dtype=torch.float32), 10.0, OPTS)
    assert geo.elevation == 12.5


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (dict(elevation=90.0), ValueError, r"elevation=90.0 must be an angle in degrees in \(-90, 90\)"),
        (dict(elevation=math.nan), ValueError, r"elevation=nan must be an angle"),
        (dict(elevation=[1.0]), TypeError, r"elevation must be a number"),
        (dict(center=math.inf), ValueError, r"center=inf must be finite or None"),
        (dict(background=math.nan), ValueError, r"background=nan must be finite"),
        (dict(max_stretch=0.0), ValueError, r"max_stretch=0.0 must be a number > 0"),
    ],
)
def test_options_checked_up_front(kwargs: dict[str, object], error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        SynthesisOptions(**kwargs)  # type: ignore[arg-type]
