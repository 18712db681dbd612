"""RandomTurntableRotation as a differentiable augmentation layer: a random rotation θ per batch.

Each training sample is a pair of seed views (0° and α) of one object with their
correspondences, computed once. At every step the library's
:class:`torch_eigview.warp.RandomTurntableRotation` draws one θ for the batch
(``same_on_batch=True``) and synthesizes the view of each object turned by θ about the
vertical axis (Eq. 2), so the network sees new poses without new images. The warp is a
differentiable function of the seed images (bilinear weights), so a loss on the augmented
views reaches the seed views.

Run: ``python examples/warp_augmentation.py [--root DIR] [--quick]``
"""

from __future__ import annotations

import argparse
import time

import torch

from torch_eigview import CoilFolder, estimate_correspondence
from torch_eigview.datasets import find_coil_root
from torch_eigview.warp import RandomTurntableRotation


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    parser.add_argument("--alpha", type=float, default=10.0)
    parser.add_argument("--max-theta", type=float, default=20.0)
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="2 objects, 2 steps (for tests)")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()

    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    objects = folder.objects[:2] if args.quick else folder.objects[:8]
    steps = 2 if args.quick else args.steps
    view1 = torch.stack([folder.image(obj, 0.0) for obj in objects])
    view2 = torch.stack([folder.image(obj, args.alpha) for obj in objects])
    corr = estimate_correspondence(view1, view2)  # once, (B, H, W): the flow is the slow part
    augment = RandomTurntableRotation(
        args.max_theta, args.alpha, p=1.0, same_on_batch=True, generator=torch.Generator().manual_seed(0)
    )

    # A stand-in training step: gradients of a loss on the augmented views flow back to
    # the seed views (here the seed views themselves are the "parameters").
    seeds1 = view1.clone().requires_grad_(True)
    worst_gap = worst_seed_gap = 0.0
    for step in range(steps):
        params = augment.forward_parameters(seeds1.shape)  # drawn here to read θ back
        views = augment(seeds1, view2, correspondence=corr, params=params)
        theta = float(params["degrees"][0])
        assert views.shape == view1.shape
        loss = views.square().mean()
        loss.backward()
        assert seeds1.grad is not None and seeds1.grad.abs().sum() > 0
        # The synthesized view at θ against the real one, where the data set has it.
        # The same warp replayed at the nearest real view's angle (COIL-20 has one every
        # 5 degrees), so that the gap measures the synthesis, not the 5-degree grid.
        nearest = 5.0 * round(theta / 5.0)
        real = torch.stack([folder.image(obj, nearest) for obj in objects])
        at_real = {"degrees": torch.full((len(objects),), nearest, dtype=torch.float64)}
        with torch.no_grad():
            synthesized = augment(view1, view2, correspondence=corr, params=at_real)
        gap = float((synthesized - real).abs().mean())
        worst_gap = max(worst_gap, gap)
        # The baseline a synthesized view must match: the nearer seed view, copied.
        seed_gap = min(float((seed - real).abs().mean()) for seed in (view1, view2))
        worst_seed_gap = max(worst_seed_gap, seed_gap)
        print(
            f"step {step}: theta {theta:+6.2f} deg, loss {loss.item():.4f}, "
            f"|grad| on seeds {seeds1.grad.abs().sum():.3e}, mean |synthesized - real at {nearest:+.0f}| {gap:.4f} "
            f"(nearer seed view: {seed_gap:.4f})"
        )
        seeds1.grad = None

    # θ = 0 (replayed as the parameters) reproduces the first seed view.
    zero = {"degrees": torch.zeros(len(objects), dtype=torch.float64)}
    with torch.no_grad():
        identity = augment(view1, view2, correspondence=corr, params=zero)
    identity_err = float((identity - view1).abs().max())
    print(f"theta = 0: max |view - seed| {identity_err:.2e}")
    seconds = time.perf_counter() - t0
    print(f"total {seconds:.1f} s")
    return {
        "identity_err": identity_err,
        "worst_gap": worst_gap,
        "worst_seed_gap": worst_seed_gap,
        "seconds": seconds,
    }


if __name__ == "__main__":
    main()
