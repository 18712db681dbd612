"""Seed-pair geometry of many objects: the row matcher's flows batched over objects in calls
sized by their cost volumes, the records those of each object alone bit for bit, and each
object's elevation fit (and its warnings) when its records are taken."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

import torch_eigview.synthesis.seed_pairs as seed_pairs
from torch_eigview.apps.bench_scaling import smooth_views
from torch_eigview.geometry.row_matcher import volume_size
from torch_eigview.synthesis import (
    ElevationFallbackWarning,
    SynthesisOptions,
    iter_object_geometries,
    object_geometries,
    pair_geometry,
)


def _objects(n: int, size: int = 32) -> list[torch.Tensor]:
    return [smooth_views(o, 6, 1, size)[[0, 5]] for o in range(n)]


def _same(a: seed_pairs.PairGeometry, b: seed_pairs.PairGeometry) -> bool:
    fields = dataclasses.fields(a.correspondence)
    same = all(
        torch.equal(getattr(a.correspondence, f.name), getattr(b.correspondence, f.name)) for f in fields
    )
    return same and a.elevation == b.elevation


@pytest.mark.parametrize("flow", ["guided", "rows"])
@pytest.mark.parametrize("budget", [1, 3 * volume_size(32, 32, 5.0), 1 << 22])
def test_batched_flows_equal_each_object_alone(
    monkeypatch: pytest.MonkeyPatch, flow: str, budget: int
) -> None:
    """One pair a call, a few pairs a call or every pair in one: each object's records are
    its own pair_geometry's, bit for bit, and the calls are as many as the budget says."""
    objects = _objects(5)
    opts = SynthesisOptions(flow=flow)
    alone = [pair_geometry(s, 5.0, opts) for s in objects]
    calls: list[int] = []
    estimate = seed_pairs.estimate_correspondence

    def counted(view1: torch.Tensor, *args: object, **kwargs: object) -> object:
        calls.append(view1.shape[0])
        return estimate(view1, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(seed_pairs, "FLOW_BATCH_CPU", budget)
    monkeypatch.setattr(seed_pairs, "estimate_correspondence", counted)
    batched = object_geometries(objects, 5.0, opts)
    per_call = max(1, budget // (2 * volume_size(32, 32, 5.0)))
    assert calls == [min(per_call, 5 - i) for i in range(0, 5, per_call)]
    for got, want in zip(batched, alone, strict=True):
        assert len(got) == 1 and _same(got[0], want[0])


def test_pairs_per_call_follows_the_cost_volume() -> None:
    """On the CPU the row matcher's calls take the pairs whose volumes (both directions) fit
    in FLOW_BATCH_CPU; the guided flow's prior runs at most at 128 × 128; elsewhere and
    for TV-L1 every pair goes in one call."""
    seeds = torch.zeros(2, 1, 128, 128)
    guided = SynthesisOptions()
    assert seed_pairs._pairs_per_call(seeds, 10.0, guided) == 5  # 25 labels
    assert seed_pairs._pairs_per_call(seeds, 5.0, guided) == 9  # 13 labels
    assert seed_pairs._pairs_per_call(seeds, 45.0, guided) == 1  # 93 labels
    big = torch.zeros(2, 1, 512, 512)  # the prior at 128 × 128
    assert seed_pairs._pairs_per_call(big, 10.0, guided) == 5
    assert seed_pairs._pairs_per_call(big, 10.0, SynthesisOptions(flow="rows")) == 1
    deep = SynthesisOptions(flow_options={"depth": 16.0})  # 2 · ceil(16 sin 10°) + 1 = 7 labels
    assert seed_pairs._pairs_per_call(seeds, 10.0, deep) == seed_pairs.FLOW_BATCH_CPU // (2 * 7 * 128 * 128)
    assert seed_pairs._pairs_per_call(seeds, 10.0, SynthesisOptions(flow="tvl1")) is None
    assert seed_pairs._pairs_per_call(seeds.to("meta"), 10.0, guided) is None
    assert volume_size(128, 128, 10.0) == (2 * math.ceil(64 * math.sin(math.radians(10))) + 1) * 128 * 128


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
