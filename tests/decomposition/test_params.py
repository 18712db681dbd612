"""The eigenspace estimators store their arguments as given and check them when a fit
starts, as scikit-learn's estimators do: a value set after construction is checked alike."""

from __future__ import annotations

from collections.abc import Callable

import pytest
import torch

from torch_eigview.decomposition import (
    Eigenspace,
    IncrementalEigenspace,
    KernelEigenspace,
    StreamingEigenspace,
)

X = torch.rand(12, 10, generator=torch.Generator().manual_seed(0), dtype=torch.float64)

FITS: dict[str, Callable[[object], object]] = {
    "fit": lambda est: est.fit(X),  # type: ignore[attr-defined]
    "fit_transform": lambda est: est.fit_transform(X),  # type: ignore[attr-defined]
}


@pytest.mark.parametrize("call", sorted(FITS))
@pytest.mark.parametrize(
    ("make", "name", "bad", "error", "match"),
    [
        (lambda: Eigenspace(3), "n_components", 0, ValueError, r"n_components=0 must be >= 1"),
        (lambda: Eigenspace(3), "solver", "eig", ValueError, r"solver='eig' must be one of"),
        (lambda: Eigenspace(3), "oversample", -1, ValueError, r"oversample=-1 must be >= 0"),
        (lambda: StreamingEigenspace(3), "solver", "svd", ValueError, r"solver='svd' must be one of"),
        (lambda: StreamingEigenspace(3), "max_views", 0, ValueError, r"max_views=0 must be >= 1"),
        (lambda: StreamingEigenspace(3), "n_iter", 1.5, TypeError, r"n_iter must be an int"),
        (lambda: KernelEigenspace(3), "kernel", "sigmoid", ValueError, r"kernel='sigmoid' must be one of"),
        (lambda: KernelEigenspace(3), "gamma", -1.0, ValueError, r"gamma=-1.0 must be a finite number > 0"),
        (lambda: KernelEigenspace(3), "nystrom", 0, ValueError, r"nystrom=0 must be >= 1"),
        (
            lambda: IncrementalEigenspace(3),
            "max_rank",
            2,
            ValueError,
            r"max_rank=2 must be at least n_components=3",
        ),
        (lambda: IncrementalEigenspace(3), "keep_codes", "yes", TypeError, r"keep_codes must be a bool"),
    ],
)
def test_arguments_are_stored_as_given_and_checked_by_fit(
    make: Callable[[], object], name: str, bad: object, error: type[Exception], match: str, call: str
) -> None:
    est = make()
    setattr(est, name, bad)  # as set_params or a constructor argument would
    assert getattr(est, name) == bad
    if call == "fit_transform" and not hasattr(est, "fit_transform"):
        pytest.skip(f"{type(est).__name__} has no fit_transform")
    with pytest.raises(error, match=match):
        FITS[call](est)
    assert getattr(est, name) == bad  # fit leaves the argument as given


def test_incremental_partial_fit_checks_too() -> None:
    est = IncrementalEigenspace(3, max_rank=2)
    with pytest.raises(ValueError, match=r"max_rank=2 must be at least n_components=3"):
        est.partial_fit(X)
