"""A classifier trained on top of a frozen EigenProjection: the eigenspace as a drop-in layer.

The eigenspace is fitted on views synthesized from two real views per object (0° and α);
a small MLP learns to name the object from the k coefficients, trained on the synthesized
views and tested on the real views at −45°..45°. Along the way the script checks what a
frozen layer promises: its buffers never change and get no gradient, gradients still reach
the input images, and it works under ``torch.compile``, after ``.to(dtype)`` (and
``.to(device)`` with CUDA), and through a ``state_dict`` round trip.

Run: ``python examples/train_frozen_features.py [--root DIR] [--quick]``
"""

from __future__ import annotations

import argparse
import copy
import io
import time

import torch
from torch import nn

from torch_eigview import CoilFolder, EigenProjection, Eigenspace, SynthesisOptions, synthesize_views
from torch_eigview.datasets import find_coil_root

TEST_ANGLES = [float(a) for a in range(-45, 50, 5)]


def unit_rows(x: torch.Tensor) -> torch.Tensor:
    v = x.flatten(1)
    return v / v.norm(dim=1, keepdim=True)


def fit_projection(
    folder: CoilFolder,
    objects: list[int],
    alpha: float,
    thetas: list[float],
    k: int,
    options: SynthesisOptions | None = None,
) -> tuple[EigenProjection, torch.Tensor, torch.Tensor]:
    """The frozen projection and its training data: (views (M, C, H, W), class indices (M,))."""
    views, classes = [], []
    for i, obj in enumerate(objects):
        seeds = folder.images(obj, [0.0, alpha])
        views.append(synthesize_views(seeds, alpha, thetas, options).views)
        classes += [i] * len(thetas)
    x = torch.cat(views)
    space = Eigenspace(k).fit(unit_rows(x))
    projection = EigenProjection(
        space.mean_, space.components_, space.eigenvalues_, tuple(x.shape[1:]), unit_norm=True
    )
    return projection, x, torch.tensor(classes)


def make_model(projection: EigenProjection, n_classes: int) -> nn.Sequential:
    """The frozen projection, then a trainable head: BatchNorm (the coefficients' scales
    differ by the eigenvalues) and a 2-layer MLP."""
    k = projection.n_components
    return nn.Sequential(projection, nn.BatchNorm1d(k), nn.Linear(k, 64), nn.ReLU(), nn.Linear(64, n_classes))


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    parser.add_argument("--alpha", type=float, default=5.0)
    parser.add_argument("--components", type=int, default=15)
    parser.add_argument("--epochs", type=int, default=60)
    parser.add_argument(
        "--quick", action="store_true", help="3 objects, untilted camera, fewer views and epochs (for tests)"
    )
    parser.add_argument("--compile-backend", default="inductor", help="torch.compile backend")
    args = parser.parse_args(argv)
    torch.manual_seed(0)
    t0 = time.perf_counter()

    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    objects = folder.objects[:3] if args.quick else folder.objects
    thetas = [float(t) for t in range(-20, 21, 5 if args.quick else 1)]
    epochs = 40 if args.quick else args.epochs
    # Quick: the paper's untilted camera (rows stay rows) skips the 2D map refinement.
    options = SynthesisOptions(elevation=0.0) if args.quick else SynthesisOptions()
    projection, x_train, y_train = fit_projection(
        folder, objects, args.alpha, thetas, args.components, options
    )
    print(f"fitted {projection} on {len(x_train)} synthesized views of {len(objects)} objects")

    model = make_model(projection, len(objects))
    frozen = {name: b.clone() for name, b in projection.state_dict().items() if isinstance(b, torch.Tensor)}
    trainable = [p for p in model.parameters() if p.requires_grad]
    assert list(projection.parameters()) == [], "the projection must hold buffers only"
    optimizer = torch.optim.Adam(trainable, lr=1e-2)
    for epoch in range(epochs):
        optimizer.zero_grad()
        loss = nn.functional.cross_entropy(model(x_train), y_train)
        loss.backward()
        optimizer.step()
        if epoch % max(1, epochs // 4) == 0 or epoch == epochs - 1:
            print(f"epoch {epoch:4d} loss {loss.item():.4f}")

    # The frozen layer: bit-identical buffers, no gradient ever stored on them.
    for name, before in frozen.items():
        assert torch.equal(projection.state_dict()[name], before), f"buffer {name} changed"
    assert all(b.grad is None and not b.requires_grad for b in projection.buffers())
    print("projection buffers unchanged after training, no gradients on them")

    # Gradients still flow through the layer to the images (e.g. for adversarial or
    # saliency uses, or a learnable augmentation before it).
    x_test = torch.cat([folder.images(obj, TEST_ANGLES) for obj in objects])
    y_test = torch.arange(len(objects)).repeat_interleave(len(TEST_ANGLES))
    probe = x_test[:4].clone().requires_grad_(True)
    model(probe).logsumexp(dim=1).sum().backward()
    assert probe.grad is not None and probe.grad.abs().sum() > 0
    print(f"gradient reaches the input images: |grad| = {probe.grad.abs().sum():.3e}")

    model.eval()
    with torch.no_grad():
        logits = model(x_test)
        accuracy = 100.0 * float((logits.argmax(dim=1) == y_test).double().mean())
    print(f"test accuracy on {len(x_test)} real views (-45..45 deg): {accuracy:.2f}%")

    # torch.compile gives the same logits.
    compiled = torch.compile(model, backend=args.compile_backend)
    with torch.no_grad():
        compile_err = float((compiled(x_test) - logits).abs().max() / logits.abs().max())
    assert compile_err < 1e-4, compile_err
    print(f"torch.compile ({args.compile_backend}) max relative diff {compile_err:.2e}")

    # .to(dtype) converts the buffers with the head; .to(device) where CUDA exists.
    double = copy.deepcopy(model).double()
    with torch.no_grad():
        dtype_err = float((double(x_test.double()).float() - logits).abs().max() / logits.abs().max())
    assert double[0].components.dtype == torch.float64 and dtype_err < 1e-4, dtype_err
    print(f".to(float64) max relative diff {dtype_err:.2e}")
    if torch.cuda.is_available():
        cuda = copy.deepcopy(model).to("cuda")
        with torch.no_grad():
            cuda_err = float((cuda(x_test.cuda()).cpu() - logits).abs().max() / logits.abs().max())
        assert cuda_err < 1e-3, cuda_err  # TF32 matmuls may be on
        print(f".to(cuda) max relative diff {cuda_err:.2e}")

    # state_dict round trip into a fresh model whose projection starts as zeros: the
    # buffers and the image shape (extra state) come back from the file.
    buffer = io.BytesIO()
    torch.save(model.state_dict(), buffer)
    buffer.seek(0)
    n, k = projection.in_features, projection.n_components
    blank = EigenProjection(torch.zeros(n), torch.zeros(k, n), torch.ones(k))
    restored = make_model(blank, len(objects))
    restored.load_state_dict(torch.load(buffer, weights_only=True))
    restored.eval()
    assert restored[0].image_shape == projection.image_shape and restored[0].unit_norm
    with torch.no_grad():
        assert torch.equal(restored(x_test), logits)
    print("state_dict round trip: identical logits")
    seconds = time.perf_counter() - t0
    print(f"total {seconds:.1f} s")
    return {"accuracy": accuracy, "compile_err": compile_err, "dtype_err": dtype_err, "seconds": seconds}


if __name__ == "__main__":
    main()
