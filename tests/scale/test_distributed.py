"""Tests for ``fit_distributed``: two gloo processes on 127.0.0.1 against one process."""

from __future__ import annotations

import datetime
import socket
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp

from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.streaming import StreamingEigenspace
from torch_eigview.scale.distributed import fit_distributed

pytestmark = pytest.mark.skipif(not dist.is_available(), reason="torch.distributed not available")

K = 6


def _data() -> torch.Tensor:
    """(50, 300) float64 views with a decaying spectrum; rank 0 gets 20 rows, rank 1 30."""
    gen = torch.Generator().manual_seed(0)
    latent = torch.randn(50, 20, generator=gen, dtype=torch.float64) * 0.7 ** torch.arange(
        20, dtype=torch.float64
    )
    return latent @ torch.randn(20, 300, generator=gen, dtype=torch.float64) + 2.0


def _shard(rank: int) -> torch.Tensor:
    x = _data()
    return x[:20] if rank == 0 else x[20:]


def _init(rank: int, world: int, port: int, timeout_s: float) -> None:
    dist.init_process_group(
        "gloo",
        init_method=f"tcp://127.0.0.1:{port}",
        rank=rank,
        world_size=world,
        timeout=datetime.timedelta(seconds=timeout_s),
    )


def _worker(rank: int, world: int, port: int, out: str) -> None:
    _init(rank, world, port, 30)
    results: dict[str, object] = {}
    try:
        exact = fit_distributed(_shard(rank), K)
        results["exact"] = (exact.mean_, exact.components_, exact.eigenvalues_, exact.n_samples_)
        rand = fit_distributed(_shard(rank), K, solver="randomized", n_iter=3, seed=1)
        results["randomized"] = (rand.components_, rand.eigenvalues_)
        for case, views in (
            ("empty", _shard(rank) if rank == 0 else torch.empty(0, 300, dtype=torch.float64)),
            ("size", _shard(rank) if rank == 0 else _shard(rank)[:, :299]),
        ):
            try:
                fit_distributed(views, K)
                results[case] = "no error"
            except ValueError as err:
                results[case] = str(err)
        try:  # a different k on one rank would abort a later collective of another size
            fit_distributed(_shard(rank), K + rank)
            results["n_components"] = "no error"
        except ValueError as err:
            results["n_components"] = str(err)
        # The group still works after the errors, on every rank.
        results["after"] = fit_distributed(_shard(rank), K).eigenvalues_
    finally:
        dist.destroy_process_group()
    torch.save(results, Path(out) / f"rank{rank}.pt")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def ranks(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, object]]:
    out = tmp_path_factory.mktemp("dist")
    mp.spawn(_worker, args=(2, _free_port(), str(out)), nprocs=2, join=True)
    return [torch.load(out / f"rank{r}.pt", weights_only=False) for r in range(2)]


def _max_angle(a: torch.Tensor, b: torch.Tensor) -> float:
    """Largest principal angle (radians) between the row spaces of a and b (orthonormal rows)."""
    s = torch.linalg.svdvals(a @ b.T).clamp(max=1.0)
    return float(torch.arccos(s.min()))


@pytest.mark.slow
def test_exact_equals_single_process(ranks: list[dict[str, object]]) -> None:
    ref = Eigenspace(K).fit(_data())
    for result in ranks:
        mean, components, eigvals, n_samples = result["exact"]  # type: ignore[misc]
        assert n_samples == 50
        torch.testing.assert_close(mean, ref.mean_, rtol=1e-10, atol=1e-10)
        torch.testing.assert_close(eigvals, ref.eigenvalues_, rtol=1e-5, atol=0)
        assert _max_angle(components, ref.components_) < 1e-4
        torch.testing.assert_close(components, ref.components_, rtol=1e-6, atol=1e-6)  # same signs


@pytest.mark.slow
def test_randomized_equals_streaming(ranks: list[dict[str, object]]) -> None:
    ref = StreamingEigenspace(K, solver="randomized", n_iter=3, seed=1).fit(_data())
    exact = Eigenspace(K).fit(_data())
    for result in ranks:
        components, eigvals = result["randomized"]  # type: ignore[misc]
        torch.testing.assert_close(eigvals, ref.eigenvalues_, rtol=1e-8, atol=0)
        assert _max_angle(components, ref.components_) < 1e-6
        assert _max_angle(components, exact.components_) < 1e-4
        torch.testing.assert_close(eigvals, exact.eigenvalues_, rtol=1e-5, atol=0)


@pytest.mark.slow
def test_bad_input_raises_on_every_rank(ranks: list[dict[str, object]]) -> None:
    for result in ranks:
        assert "rank 1: views holds no views" in str(result["empty"])
        assert "same view shape and dtype on every rank" in str(result["size"])
        assert "(P_r, 299)" in str(result["size"])
        assert f"rank 1: n_components={K + 1} differs from rank 0's {K}" in str(result["n_components"])
        torch.testing.assert_close(result["after"], result["exact"][2])  # type: ignore[index]


def test_needs_initialized_group() -> None:
    if dist.is_initialized():
        pytest.skip("a process group is already initialized")
    with pytest.raises(RuntimeError, match="init_process_group"):
        fit_distributed(_data(), K)


def _stall_worker(rank: int, world: int, port: int, out: str) -> None:
    """Rank 1 stalls past the group's 3 s timeout before its first collective."""
    import time

    _init(rank, world, port, 3)
    t0 = time.perf_counter()
    try:
        if rank == 1:
            time.sleep(8)
        fit_distributed(_shard(rank), K)
        result: object = "no error"
    except (TimeoutError, RuntimeError) as err:
        result = (type(err).__name__, str(err))
    elapsed = time.perf_counter() - t0
    torch.save({"result": result, "elapsed": elapsed}, Path(out) / f"stall{rank}.pt")
    try:
        dist.destroy_process_group()
    except Exception:  # the group may be broken already; the results are saved
        pass


@pytest.mark.slow
def test_collective_timeout_is_an_error_on_every_rank(tmp_path: Path) -> None:
    """A stalled rank: the waiting rank raises when the timeout passes, no hang; the stalled
    rank finds its peer gone and raises too."""
    mp.spawn(_stall_worker, args=(2, _free_port(), str(tmp_path)), nprocs=2, join=True)
    r0, r1 = (torch.load(tmp_path / f"stall{r}.pt", weights_only=False) for r in range(2))
    assert r0["result"][0] == "TimeoutError", r0
    assert "rank 0" in r0["result"][1] and "timeout" in r0["result"][1]
    assert r0["elapsed"] < 8  # ended by the 3 s timeout, not by rank 1 coming back
    assert r1["result"] != "no error", r1
    assert r1["elapsed"] < 8 + 30
