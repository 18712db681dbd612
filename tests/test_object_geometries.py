"""Seed-pair geometry of many objects: the row matcher's flows batched over objects, the
records those of each object alone bit for bit whatever the batch, and each object's
elevation fit (and its warnings) when its records are taken."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

import torch_eigview._tuning as _tuning
import torch_eigview.synthesis.seed_pairs as seed_pairs
from torch_eigview.geometry.row_matcher import volume_size
from torch_eigview.synthesis import (
    ElevationFallbackWarning,
    SynthesisOptions,
    iter_object_geometries,
    object_geometries,
    pair_geometry,
)

from tests.helpers import smooth_views


def _objects(n: int, size: int = 32) -> list[torch.Tensor]:
    return [smooth_views(o, 6, 1, size)[[0, 5]] for o in range(n)]


def _same(a: seed_pairs.PairGeometry, b: seed_pairs.PairGeometry) -> bool:
    fields = dataclasses.fields(a.correspondence)
    same = all(
        torch.equal(getattr(a.correspondence, f.name), getattr(b.correspondence, f.name)) for f in fields
    )
    return same and a.elevation == b.elevation


@pytest.mark.parametrize("flow", ["guided", "rows"])
@pytest.mark.parametrize("budget", [1, 6 * volume_size(32, 32, 5.0), None])
def test_batched_flows_equal_each_object_alone(
    monkeypatch: pytest.MonkeyPatch, flow: str, budget: int | None
) -> None:
    """One pair a call (a tiny batch budget), a few pairs a call, or the default budget
    (all five pairs of these small views in one call): each object's records are its own
    pair_geometry's, bit for bit."""
    objects = _objects(5)
    opts = SynthesisOptions(flow=flow)
    alone = [pair_geometry(s, 5.0, opts) for s in objects]
    calls: list[int] = []
    estimate = seed_pairs.estimate_correspondence

    def counted(view1: torch.Tensor, *args: object, **kwargs: object) -> object:
        calls.append(view1.shape[0])
        return estimate(view1, *args, **kwargs)  # type: ignore[arg-type]

    if budget is not None:
        monkeypatch.setattr(_tuning, "FLOW_BATCH_CPU", budget)
    monkeypatch.setattr(seed_pairs, "estimate_correspondence", counted)
    batched = object_geometries(objects, 5.0, opts)
    # The batching took effect: one pair a call, a few (3 + 2), or all five in one.
    assert calls == {1: [1] * 5, None: [5]}.get(budget, [3, 2])
    for got, want in zip(batched, alone, strict=True):
        assert len(got) == 1 and _same(got[0], want[0])


@pytest.mark.parametrize("budget", [1, None])
def test_guided_flow_with_a_reduced_prior_batches_the_same(
    monkeypatch: pytest.MonkeyPatch, budget: int | None
) -> None:
    """Views larger than the guided flow's ``prior_side`` have their prior matched at a
    reduced size; batched over objects, one pair a call or all in one, the records are
    still each object's own."""
    objects = _objects(3, size=48)
    opts = SynthesisOptions(flow_options={"prior_side": 24, "num_warp": 3, "num_iter": 5})
    alone = [pair_geometry(s, 5.0, opts) for s in objects]
    if budget is not None:
        monkeypatch.setattr(_tuning, "FLOW_BATCH_CPU", budget)
    batched = object_geometries(objects, 5.0, opts)
    for got, want in zip(batched, alone, strict=True):
        assert len(got) == 1 and _same(got[0], want[0])
    full = pair_geometry(objects[0], 5.0, SynthesisOptions())  # the prior at full size
    assert not torch.equal(full[0].correspondence.disparity_12, alone[0][0].correspondence.disparity_12)


def test_volume_size_counts_labels_times_pixels() -> None:
    assert volume_size(128, 128, 10.0) == (2 * math.ceil(64 * math.sin(math.radians(10))) + 1) * 128 * 128
    assert volume_size(128, 128, 10.0, depth=16.0) == 7 * 128 * 128  # 2 · ceil(16 sin 10°) + 1 labels


def test_iter_checks_at_the_call_and_warns_per_object(monkeypatch: pytest.MonkeyPatch) -> None:
    """Bad seeds are refused when the iterator is made; each object's elevation warning is
    raised when its own records are taken, after the batched flows."""
    objects = _objects(3)
    with pytest.raises(ValueError, match="at least 2 views"):
        iter_object_geometries([objects[0], objects[1][:1]], 5.0)
    monkeypatch.setattr(seed_pairs, "estimate_elevation", lambda *a, **k: torch.tensor([math.nan]))
    records = iter_object_geometries(objects, 5.0)
    for _ in objects:
        with pytest.warns(ElevationFallbackWarning) as caught:
            (geo,) = next(records)
        assert len(caught) == 1 and geo.elevation == 0.0
    assert next(records, None) is None
