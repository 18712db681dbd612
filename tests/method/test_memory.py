"""The memory a fit needs and the memory this process can still have."""

from __future__ import annotations

import subprocess
import sys

import pytest

from torch_eigview.method.memory import MemoryBudgetError, available_memory, check_memory, fit_estimate

SIZES = dict(objects=80, views=360, held_out=40, image_shape=(3, 128, 128), itemsize=4, components=15)


def test_a_merged_fit_does_not_grow_with_the_objects() -> None:
    kw = dict(max_views=4096, max_rank=256, kernel=False, workers=2)
    small, large = fit_estimate(**{**SIZES, "objects": 20}, **kw), fit_estimate(**SIZES, **kw)  # type: ignore[arg-type]
    assert small.incremental and large.incremental
    assert large.bytes < 1.2 * small.bytes
    held = fit_estimate(**{**SIZES, "objects": 5}, **kw)  # type: ignore[arg-type]
    assert not held.incremental  # 1,800 views: held at once, the exact eigenspace


def test_held_at_once_grows_with_the_views() -> None:
    kw = dict(max_views=10**9, max_rank=256, kernel=False, workers=0)
    small, large = fit_estimate(**{**SIZES, "objects": 20}, **kw), fit_estimate(**SIZES, **kw)  # type: ignore[arg-type]
    assert large.bytes > 3.5 * small.bytes


def test_the_address_space_limit_bounds_what_is_available() -> None:
    code = (
        "import resource; resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30));"
        "from torch_eigview.method.memory import available_memory; free, bound = available_memory();"
        "print(free < 3 << 30, bound)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    ).stdout
    assert out.split(maxsplit=1) == ["True", "the address-space limit, ulimit -v\n"]


def test_check_names_the_sizes_and_the_remedies(monkeypatch: pytest.MonkeyPatch) -> None:
    import torch_eigview.method.memory as memory

    estimate = fit_estimate(**SIZES, max_views=10**9, max_rank=256, kernel=False, workers=0)  # type: ignore[arg-type]
    monkeypatch.setattr(memory, "available_memory", lambda: (1 << 30, "the container's memory limit"))
    with pytest.raises(
        MemoryBudgetError, match=r"80 objects x 360 views and 40 held out .*\(3, 128, 128\).*held all at once"
    ) as info:
        check_memory(estimate, "try smaller images")
    assert "1.00 GiB are available (the container's memory limit); try smaller images" in str(info.value)
    assert isinstance(info.value, ValueError)  # the commands' exit status 2
    free, bound = available_memory()
    assert free > 0 and bound
