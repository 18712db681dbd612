"""A classifier head trained on the frozen eigenspace layer: the layer in a training loop.

The eigenspace is the paper's: a :class:`~torch_eigview.method.FewViewEigenspace` fitted
from two seed views per object (0° and α), its gallery synthesized between them. Its
``to_module()`` is the frozen first layer of a model whose head (a LayerNorm, then a 2-layer
MLP) learns to name the object from the same two seed views per object, read by a
``DataLoader`` over a :class:`~torch_eigview.datasets.ViewDataset` of the folder: in
mini-batches of objects, each seed pair turned by a random angle per step
(:class:`~torch_eigview.warp.RandomTurntableRotation`, the synthesis of Eq. 2 as an
augmentation, over the angles the gallery spans), on CUDA when present, under autocast
(bfloat16 on the CPU, float16 with a gradient scaler on CUDA). Both are then tested on the
same real views, −45°..45° (COIL-20's test views): the head's accuracy next to the
nearest-neighbour recognizer's over the synthesized gallery.

Along the way it checks what a frozen layer promises: its buffers never change and get no
gradient, gradients still reach the input images, ``torch.compile`` gives the eager
logits, float64 inputs give the float32 ones, and a ``state_dict`` round trip restores it.

The figures go to a result record, ``examples/results/train_frozen_features.json`` by
default (``--record ''`` for none).

Run: ``python examples/train_frozen_features.py [--root DIR | --manifest CSV] [--quick]``
"""

from __future__ import annotations

import argparse
import io
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.utils.data import DataLoader, Subset

from torch_eigview import (
    EigenProjection,
    FewViewEigenspace,
    SynthesisOptions,
    environment_info,
    estimate_correspondence,
)
from torch_eigview.datasets import ViewDataset, ViewManifest, background_rule, find_coil_root
from torch_eigview.files import check_output_path, write_json
from torch_eigview.warp import RandomTurntableRotation

RECORD = Path(__file__).resolve().parent / "results" / "train_frozen_features.json"
TEST_RANGE = 45.0  # the test views: azimuths within ±45° of 0 (COIL-20's 19 per object)
AROUND = 20.0  # the augmentation turns the seeds up to this far past them, as the gallery's synth


def make_model(layer: nn.Module, k: int, n_classes: int) -> nn.Sequential:
    """The frozen layer, then a trainable head: LayerNorm (the coefficients' scales differ
    by the eigenvalues; normalized per view, so a mini-batch of a few objects trains as well
    as a large one, which BatchNorm's batch statistics do not) and a 2-layer MLP."""
    return nn.Sequential(layer, nn.LayerNorm(k), nn.Linear(k, 64), nn.ReLU(), nn.Linear(64, n_classes))


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except RuntimeError:
        raise ValueError(f"--device {name!r} must be auto, cpu, cuda or cuda:N") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"--device {name}: no CUDA device is available; use --device cpu")
    return device


def autocast_dtype(name: str, device: torch.device) -> torch.dtype | None:
    """``--amp``: auto is bfloat16 on the CPU, float16 on CUDA; none turns autocast off."""
    if name == "none":
        return None
    if name == "auto":
        return torch.float16 if device.type == "cuda" else torch.bfloat16
    return {"bf16": torch.bfloat16, "fp16": torch.float16}[name]


def labels_of(batch: dict[str, Any], names: list[str], device: torch.device) -> torch.Tensor:
    """The (B,) class indices of a collated ViewDataset batch: its object names' places in ``names``."""
    return torch.tensor([names.index(o) for o in batch["object"]], device=device)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    source = parser.add_mutually_exclusive_group()
    source.add_argument(
        "--root",
        help="a COIL folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    source.add_argument("--manifest", help="a manifest CSV of the views, in place of a COIL folder")
    parser.add_argument("--alpha", type=float, default=5.0, help="the second seed view's azimuth")
    parser.add_argument("--components", type=int, default=15)
    parser.add_argument("--epochs", type=int, default=150)
    parser.add_argument("--batch-size", type=int, default=8)
    parser.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda or cuda:N")
    parser.add_argument(
        "--amp",
        choices=["auto", "bf16", "fp16", "none"],
        default="auto",
        help="autocast dtype (auto: bf16 on the CPU, fp16 on CUDA)",
    )
    parser.add_argument("--compile-backend", default="inductor", help="torch.compile backend")
    parser.add_argument(
        "--quick", action="store_true", help="3 objects, untilted camera, fewer epochs (for tests)"
    )
    parser.add_argument(
        "--record",
        default=str(RECORD),
        help="the JSON result record (default examples/results/train_frozen_features.json; '' for none)",
    )
    args = parser.parse_args(argv)
    try:
        device = pick_device(args.device)
    except (RuntimeError, ValueError) as exc:
        parser.error(str(exc))
    amp = autocast_dtype(args.amp, device)
    if args.record:
        if args.record == str(RECORD):
            RECORD.parent.mkdir(exist_ok=True)
        try:  # an unwritable record: say so before the work, not after it
            check_output_path(args.record, "--record")
        except ValueError as exc:
            parser.error(str(exc))
    torch.manual_seed(0)
    t0 = time.perf_counter()

    try:  # a missing folder or file: say where the images go, not a traceback
        if args.manifest:
            manifest = ViewManifest.from_csv(args.manifest)
        else:
            manifest = ViewManifest.from_coil(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    if args.quick:
        keep = manifest.objects[:3]
        manifest = ViewManifest(
            [e for e in manifest if e.object in keep], name=f"{manifest.name} (3 objects)"
        )
    seeds = [0.0, args.alpha]
    epochs = 60 if args.quick else args.epochs

    # The eigenspace from two seed views per object (Sec. 4.1), then its frozen layer.
    # Quick: the paper's untilted camera (rows stay rows) skips the 2D map refinement.
    options = SynthesisOptions(elevation=0.0) if args.quick else None
    est = FewViewEigenspace(args.components, options=options).fit_manifest(manifest, seeds)
    names = list(est.label_names_ or [])
    layer = est.to_module()  # unit_norm as fitted
    print(f"fitted {layer} from {len(seeds)} seed views of {len(names)} objects")

    # One ViewDataset of the folder, read as the fit read it; split by azimuth.
    prep = est.preprocessing_
    assert prep is not None
    background = background_rule(prep.background, prep.colour, prep.tolerance)
    dataset = ViewDataset(manifest, prep.size, channels=prep.channels, background=background)
    wrapped = [(e.azimuth + 180.0) % 360.0 - 180.0 for e in manifest]
    train_idx = [i for i, a in enumerate(wrapped) if any(abs(a - s) < 1e-6 for s in seeds)]
    test_idx = [i for i, a in enumerate(wrapped) if abs(a) <= TEST_RANGE]
    test = DataLoader(Subset(dataset, test_idx), batch_size=64)

    # The training data: each object's seed pair, read once through the DataLoader, and its
    # correspondences (the slow part, once); every step turns a mini-batch of pairs.
    view1: list[torch.Tensor | None] = [None] * len(names)
    view2: list[torch.Tensor | None] = [None] * len(names)
    for batch in DataLoader(Subset(dataset, train_idx), batch_size=64):
        for image, name, azimuth in zip(
            batch["image"], batch["object"], batch["azimuth"].tolist(), strict=True
        ):
            first = abs((azimuth - seeds[0] + 180.0) % 360.0 - 180.0) < 1e-6
            (view1 if first else view2)[names.index(name)] = image
    missing = [n for n, a, b in zip(names, view1, view2, strict=True) if a is None or b is None]
    if missing:
        parser.error(f"objects {missing} lack a view at the seed azimuths {seeds}")
    seed1 = torch.stack(view1).to(device)  # type: ignore[arg-type]
    seed2 = torch.stack(view2).to(device)  # type: ignore[arg-type]
    corr = estimate_correspondence(seed1, seed2)
    warp_options: dict[str, Any] = {"elevation": 0.0} if args.quick else {}  # as the fit's options
    augment = RandomTurntableRotation((-AROUND, args.alpha + AROUND), args.alpha, p=1.0, **warp_options)
    order = torch.Generator().manual_seed(0)

    model = make_model(layer, layer.n_components, len(names)).to(device)
    frozen = {name: b.clone() for name, b in layer.state_dict().items() if isinstance(b, torch.Tensor)}
    assert list(layer.parameters()) == [], "the layer must hold buffers only"
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    scaler = torch.amp.GradScaler(device.type, enabled=amp == torch.float16)
    for epoch in range(epochs):
        model.train()
        total, count = 0.0, 0
        for batch_objects in torch.randperm(len(names), generator=order).split(args.batch_size):
            y = batch_objects.to(device)
            with torch.no_grad():  # the augmentation: each pair at its own random angle
                x = augment(seed1[y], seed2[y], correspondence=corr[y.cpu()])
            with torch.autocast(device.type, dtype=amp or torch.float32, enabled=amp is not None):
                logits = model(x)  # the layer casts the batch to its float32 buffers
            loss = nn.functional.cross_entropy(logits.float(), y)
            optimizer.zero_grad()
            scaler.scale(loss).backward()
            scaler.step(optimizer)
            scaler.update()
            total, count = total + float(loss.detach()) * len(y), count + len(y)
        if epoch % max(1, epochs // 4) == 0 or epoch == epochs - 1:
            print(f"epoch {epoch:4d} loss {total / count:.4f}")

    # The frozen layer: bit-identical buffers, no gradient ever stored on them.
    for name, before in frozen.items():
        assert torch.equal(layer.state_dict()[name].cpu(), before.cpu()), f"buffer {name} changed"
    assert all(b.grad is None and not b.requires_grad for b in layer.buffers())
    print("layer buffers unchanged after training, no gradients on them")

    # Both on the same real test views: the head, and the nearest-neighbour recognizer.
    model.eval()
    xs, ys, head_right, nn_right = [], [], 0, 0
    with torch.no_grad():
        for batch in test:
            x, y = batch["image"].to(device), labels_of(batch, names, device)
            with torch.autocast(device.type, dtype=amp or torch.float32, enabled=amp is not None):
                head_right += int((model(x).argmax(dim=1) == y).sum())
            nn_right += int((est.predict(batch["image"]).labels.to(device) == y).sum())
            xs.append(x)
            ys.append(y)
    x_test, n_test = torch.cat(xs), len(test_idx)
    accuracy, nn_accuracy = 100.0 * head_right / n_test, 100.0 * nn_right / n_test
    amp_name = "off" if amp is None else str(amp).removeprefix("torch.")
    print(f"test views: {n_test} real views at -{TEST_RANGE:g}..{TEST_RANGE:g} deg of {len(names)} objects")
    print(f"  head on the frozen layer ({device}, autocast {amp_name}): {accuracy:.2f}%")
    print(f"  nearest neighbour over the synthesized gallery: {nn_accuracy:.2f}%")

    # Gradients still flow through the layer to the images (adversarial or saliency uses,
    # or a learnable augmentation before it).
    probe = x_test[:4].clone().requires_grad_(True)
    model(probe).logsumexp(dim=1).sum().backward()
    assert probe.grad is not None and probe.grad.abs().sum() > 0
    print(f"gradient reaches the input images: |grad| = {probe.grad.abs().sum():.3e}")

    with torch.no_grad():
        logits = model(x_test)  # float32, no autocast: the reference
        # torch.compile gives the same logits.
        compiled = torch.compile(model, backend=args.compile_backend)
        compile_err = float((compiled(x_test) - logits).abs().max() / logits.abs().max())
        # float64 inputs are cast to the layer's float32 (a drop-in layer takes them as they come).
        dtype_err = float((model(x_test.double()) - logits).abs().max() / logits.abs().max())
    assert compile_err < 1e-4, compile_err
    assert dtype_err < 1e-6, dtype_err
    print(f"torch.compile ({args.compile_backend}) max relative diff {compile_err:.2e}")
    print(f"float64 input max relative diff {dtype_err:.2e}")

    # state_dict round trip into a fresh model whose layer starts empty (the sizes form):
    # the buffers, the image shape and unit_norm (extra state) come back from the file.
    buffer = io.BytesIO()
    torch.save(model.state_dict(), buffer)
    buffer.seek(0)
    assert isinstance(layer, EigenProjection)  # a linear FewViewEigenspace's layer
    blank = EigenProjection(layer.in_features, layer.n_components)  # zeros, for load_state_dict
    restored = make_model(blank, layer.n_components, len(names)).to(device)
    restored.load_state_dict(torch.load(buffer, weights_only=True))
    restored.eval()
    assert restored[0].image_shape == layer.image_shape and restored[0].unit_norm == layer.unit_norm
    with torch.no_grad():
        assert torch.equal(restored(x_test), logits)
    print("state_dict round trip: identical logits")
    seconds = time.perf_counter() - t0
    print(f"total {seconds:.1f} s")
    result: dict[str, Any] = {
        "accuracy": accuracy,
        "nn_accuracy": nn_accuracy,
        "n_test": n_test,
        "n_train": len(train_idx),
        "objects": len(names),
        "epochs": epochs,
        "device": str(device),
        "autocast": amp_name,
        "compile_err": compile_err,
        "dtype_err": dtype_err,
        "seconds": seconds,
    }
    if args.record:
        write_record(args.record, argv, result, args)
    return result


def write_record(path: str, argv: list[str] | None, result: dict[str, Any], args: argparse.Namespace) -> None:
    """The result record in ``docs/make_pages.py``'s format: the table and the raw figures."""
    script = Path(__file__).resolve()
    root = script.parents[1]
    shown = script.relative_to(root).as_posix() if script.is_relative_to(root) else str(script)
    caption = (
        f"{result['objects']} objects, seed views at 0° and {args.alpha:g}°, k = {args.components}; "
        f"accuracy (%) over the {result['n_test']} real test views at −45°..45°. The head is trained "
        f"on the {result['n_train']} seed views, turned at random by up to {AROUND:g}° past them ({result['epochs']} epochs, {result['device']}, autocast "
        f"{result['autocast']}); the nearest-neighbour recognizer searches the gallery synthesized from them."
    )
    record = {
        "title": "A head trained on the frozen eigenspace layer against nearest neighbour",
        "page": "results",
        "command": shlex.join(["python", shown, *(sys.argv[1:] if argv is None else argv)]),
        "environment": environment_info(),
        "tables": [
            {
                "caption": caption,
                "columns": ["classifier", "accuracy (%)"],
                "rows": [
                    ["MLP head on the frozen layer", result["accuracy"]],
                    ["nearest neighbour (synthesized gallery)", result["nn_accuracy"]],
                ],
            }
        ],
        "run": result,
    }
    write_json(path, record, default=str)
    print(f"record written to {path}")


if __name__ == "__main__":
    main()
