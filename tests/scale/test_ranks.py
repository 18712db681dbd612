"""FewViewEigenspace.fit over the ranks of a process group (scale/ranks.py): two gloo
processes on 127.0.0.1 split the objects and end with the model one process fits, the
gallery held (gathered views) and merged (gathered eigenspace models): coefficients within
1e-5 relative (the ranks' float32 products run on other thread counts than this process's)."""

from __future__ import annotations

import datetime
import socket
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp

from torch_eigview.apps.cli import ranks_from_environment
from torch_eigview.datasets import OrthographicCamera, make_object, render_views
from torch_eigview.method import FewViewEigenspace
from torch_eigview.scale.ranks import object_shard, process_group, world

pytestmark = pytest.mark.skipif(not dist.is_available(), reason="torch.distributed not available")

SHAPES = ("ellipsoid", "egg", "head", "superquadric", "cylinder")
SYNTH = (-10.0, 20.0, 2.0)


def _seeds() -> torch.Tensor:
    camera = OrthographicCamera(24)
    return torch.stack([render_views(make_object(name, seed=2), [0.0, 10.0], camera) for name in SHAPES])


def _fit(max_views: int) -> FewViewEigenspace:
    est = FewViewEigenspace(
        6, synth=SYNTH, max_views=max_views, reject_rate=0.05, reject_poses=(-14.0, 24.0, 2.0)
    )
    return est.fit(_seeds(), [0.0, 10.0], labels=list(SHAPES))


def _summary(est: FewViewEigenspace) -> dict[str, torch.Tensor]:
    rec = est.recognizer_
    return {
        "codes": rec.codes.clone(),
        "labels": rec.labels.clone(),
        "poses": rec.poses.clone(),
        "components": est.projection_.components.clone(),
        "thresholds": rec.reject_thresholds.clone(),
    }


def _worker(rank: int, world_size: int, port: int, out: str) -> None:
    dist.init_process_group(
        "gloo",
        init_method=f"tcp://127.0.0.1:{port}",
        rank=rank,
        world_size=world_size,
        timeout=datetime.timedelta(seconds=60),
    )
    try:
        torch.save(
            {"held": _summary(_fit(4096)), "merged": _summary(_fit(40)), "shard": object_shard(len(SHAPES))},
            Path(out) / f"rank{rank}.pt",
        )
    finally:
        dist.destroy_process_group()


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def ranks(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, object]]:
    out = tmp_path_factory.mktemp("ranks")
    mp.spawn(_worker, args=(2, _port(), str(out)), nprocs=2, join=True)
    return [torch.load(out / f"rank{r}.pt", weights_only=False) for r in range(2)]


def _close(got: torch.Tensor, want: torch.Tensor, rtol: float) -> None:
    """Within ``rtol`` of ``want``'s largest finite magnitude; infinite entries (a rejection
    threshold that rejects nothing) where ``want`` has them."""
    got, want = got.double(), want.double()
    finite = torch.isfinite(want)
    assert torch.equal(torch.isfinite(got), finite) and torch.equal(got[~finite], want[~finite])
    got, want = got[finite], want[finite]
    err = float((got - want).abs().max()) / float(want.abs().max())
    assert err <= rtol, f"relative difference {err:.3g}"


@pytest.mark.slow
@pytest.mark.parametrize(("mode", "max_views", "rtol"), [("held", 4096, 1e-5), ("merged", 40, 1e-5)])
def test_two_ranks_fit_the_model_of_one_process(
    ranks: list[dict[str, object]], mode: str, max_views: int, rtol: float
) -> None:
    one = _summary(_fit(max_views))
    for result in ranks:
        got = result[mode]
        assert isinstance(got, dict)
        assert torch.equal(got["labels"], one["labels"]) and torch.equal(got["poses"], one["poses"])
        for key in ("codes", "components", "thresholds"):
            _close(got[key], one[key], rtol)
    assert [r["shard"] for r in ranks] == [range(0, 3), range(3, 5)]


def test_one_process_is_the_whole_share() -> None:
    if dist.is_initialized():
        pytest.skip("a process group is already initialized")
    assert world() == (0, 1) and object_shard(4) == range(0, 4)


def test_one_process_group_is_a_no_op() -> None:
    if dist.is_initialized():
        pytest.skip("a process group is already initialized")
    with process_group(0, 1) as rank:
        assert rank == 0 and not dist.is_initialized()
    with (
        pytest.raises(ValueError, match=r"backend must be 'gloo' or 'nccl', got 'mpi'"),
        process_group(0, 1, "mpi"),
    ):
        pass
    with pytest.raises(ValueError, match=r"rank=2 must lie in \[0, size=2\)"), process_group(2, 2):
        pass


def test_ranks_from_the_environment() -> None:
    assert ranks_from_environment({}) == (0, 1)
    assert ranks_from_environment({"RANK": "1", "WORLD_SIZE": "4"}) == (1, 4)
    with pytest.raises(ValueError, match=r"WORLD_SIZE='two' and RANK='0' must be integers"):
        ranks_from_environment({"WORLD_SIZE": "two"})
