"""NovelViewWarp as a differentiable augmentation layer: a random rotation θ per batch.

Each training sample is a pair of seed views (0° and α) of one object with their
correspondences, computed once. At every step the layer draws one θ for the batch and
synthesizes the view of each object turned by θ about the vertical axis (Eq. 2), so the
network sees new poses without new images. The warp is a differentiable function of the
seed images (bilinear weights), so a loss on the augmented views reaches the seed views.

Run: ``python examples/warp_augmentation.py [--root DIR] [--quick]``
"""

from __future__ import annotations

import argparse
import time

import torch
from torch import nn

from torch_eigview import CoilFolder, Correspondence, NovelViewWarp, estimate_correspondence
from torch_eigview.datasets import find_coil_root


class RandomTurntableRotation(nn.Module):
    """Synthesizes each pair's view at one random θ in ``[-max_theta, max_theta]`` per batch.

    Args:
        alpha: angle between the seed views (degrees).
        max_theta: largest rotation drawn (degrees from the first seed view).
        generator: the random source, for reproducible augmentations.
    """

    def __init__(self, alpha: float, max_theta: float, generator: torch.Generator | None = None) -> None:
        super().__init__()
        self.warp = NovelViewWarp(alpha)
        self.max_theta = max_theta
        self.generator = generator

    def forward(
        self, view1: torch.Tensor, view2: torch.Tensor, correspondence: Correspondence
    ) -> tuple[torch.Tensor, float]:
        """(B, C, H, W) seed views → ((B, C, H, W) views at θ, θ). Identity in eval mode (θ = 0)."""
        theta = 0.0
        if self.training:
            u = float(torch.rand((), generator=self.generator))
            theta = (2 * u - 1) * self.max_theta
        views = self.warp(view1, view2, correspondence=correspondence, thetas=[theta])
        return views[:, 0], theta


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
    augment = RandomTurntableRotation(args.alpha, args.max_theta, torch.Generator().manual_seed(0))

    # A stand-in training step: gradients of a loss on the augmented views flow back to
    # the seed views (here the seed views themselves are the "parameters").
    seeds1 = view1.clone().requires_grad_(True)
    worst_gap = 0.0
    for step in range(steps):
        views, theta = augment(seeds1, view2, corr)
        assert views.shape == view1.shape
        loss = views.square().mean()
        loss.backward()
        assert seeds1.grad is not None and seeds1.grad.abs().sum() > 0
        # The synthesized view at θ against the real one, where the data set has it.
        nearest = 5.0 * round(theta / 5.0)
        real = torch.stack([folder.image(obj, nearest) for obj in objects])
        gap = float((views.detach() - real).abs().mean())
        worst_gap = max(worst_gap, gap)
        print(
            f"step {step}: theta {theta:+6.2f} deg, loss {loss.item():.4f}, "
            f"|grad| on seeds {seeds1.grad.abs().sum():.3e}, mean |view - real at {nearest:+.0f}| {gap:.4f}"
        )
        seeds1.grad = None

    augment.eval()  # no augmentation: θ = 0 reproduces the first seed view
    with torch.no_grad():
        identity, _ = augment(view1, view2, corr)
    identity_err = float((identity - view1).abs().max())
    print(f"eval mode (theta = 0): max |view - seed| {identity_err:.2e}")
    seconds = time.perf_counter() - t0
    print(f"total {seconds:.1f} s")
    return {"identity_err": identity_err, "worst_gap": worst_gap, "seconds": seconds}


if __name__ == "__main__":
    main()
