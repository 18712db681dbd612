"""The background model: masks estimated from the border against the renderer's exact masks,
the constant background, the errors, and ViewDataset with a background model."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import skimage.io
import torch

from torch_eigview.datasets import (
    SHAPES,
    Backdrop,
    BackgroundModel,
    OrthographicCamera,
    PerspectiveCamera,
    ViewDataset,
    ViewManifest,
    make_object,
    render,
    set_background,
)
from torch_eigview.datasets.background import border_pixels
from torch_eigview.synthesis import SynthesisOptions, synthesize_views

from tests.helpers import rand


def _iou(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a & b).sum()) / float((a | b).sum())


@pytest.mark.parametrize("camera", [OrthographicCamera(48), PerspectiveCamera(48)], ids=["ortho", "persp"])
def test_estimated_masks_match_the_renderers(camera: object) -> None:
    """On the textured backdrop and ground, the border model recovers the exact masks."""
    ious = []
    for k, name in enumerate(SHAPES):
        r = render(make_object(name, seed=1), -30.0 + 17.0 * k, camera, backdrop=Backdrop(seed=k))
        assert r.image.shape == (3, 48, 48)
        est = BackgroundModel().masks(r.image[None])
        ious.append(_iou(est[0, 0], r.mask))
    assert min(ious) > 0.97, ious


def test_backdrop_leaves_the_object_and_the_default_render_unchanged() -> None:
    obj, cam = make_object("egg"), OrthographicCamera(32)
    black = render(obj, 12.0, cam)
    on = render(obj, 12.0, cam, backdrop=Backdrop())
    assert torch.equal(on.mask, black.mask)
    for c in range(3):
        assert torch.equal(on.image[c][black.mask], black.image[0][black.mask])
    assert torch.equal(set_background(on.image[None], on.mask[None, None])[0, :1], black.image)
    # The background is coloured and textured, so a brightness threshold cannot find the object.
    bg = on.image[:, ~on.mask]
    assert float(bg.std(dim=1).min()) > 0.01
    assert float((bg[2] - bg[0]).abs().mean()) > 0.1


def test_ground_is_seen_below_the_object() -> None:
    """The ground's colour fills the rows under the objects, the backdrop's those above."""
    backdrop = Backdrop(texture=0.0)
    for cam in (OrthographicCamera(40), PerspectiveCamera(40)):
        image = render(make_object("head"), 0.0, cam, backdrop=backdrop).image
        assert torch.allclose(image[:, 0, 0], torch.tensor(backdrop.colour, dtype=image.dtype))
        assert torch.allclose(image[:, -1, 0], torch.tensor(backdrop.ground_colour, dtype=image.dtype))


def test_given_background_and_tolerance() -> None:
    x = torch.zeros(1, 3, 16, 16)
    x[:, :] = torch.tensor([0.2, 0.4, 0.6]).view(1, 3, 1, 1)
    x[..., 4:12, 5:11] = 0.9
    mask = BackgroundModel(background=(0.2, 0.4, 0.6), tolerance=0.1).masks(x)
    want = torch.zeros(1, 1, 16, 16, dtype=torch.bool)
    want[..., 4:12, 5:11] = True
    assert torch.equal(mask, want)
    out, fg = BackgroundModel(fill=0.25).apply(x)
    assert torch.equal(fg, want)
    assert torch.equal(out[:, :, ~want[0, 0]], torch.full_like(out[:, :, ~want[0, 0]], 0.25))
    kept, _ = BackgroundModel(fill=None).apply(x)
    assert torch.equal(kept, x)


def test_cleaning_drops_specks_and_fills_small_holes() -> None:
    x = torch.zeros(1, 1, 40, 40, dtype=torch.float64)
    x[..., 10:30, 10:30] = 0.8
    x[..., 18:20, 18:20] = 0.0  # an object pixel of the background's colour
    x[..., 2, 35] = 0.8  # a speck of backdrop texture
    mask = BackgroundModel(border=1).masks(x)[0, 0]
    want = torch.zeros(40, 40, dtype=torch.bool)
    want[10:30, 10:30] = True
    assert torch.equal(mask, want)
    raw = BackgroundModel(border=1, min_fraction=0.0).masks(x)[0, 0]
    assert not raw[18, 18] and raw[2, 35]


def test_border_pixels_count() -> None:
    x = rand(2, 3, 10, 12, dtype=torch.float32)
    assert border_pixels(x, 2).shape == (2, 10 * 12 - 6 * 8, 3)


def test_errors_name_the_argument_and_the_value() -> None:
    x = torch.rand(2, 3, 8, 8)
    with pytest.raises(
        ValueError, match=r"masks must have shape \(B, 1, H, W\) = \(2, 1, 8, 8\).*\(2, 1, 8, 9\)"
    ):
        BackgroundModel().masks(x, torch.ones(2, 1, 8, 9, dtype=torch.bool))
    empty = torch.ones(2, 1, 8, 8, dtype=torch.bool)
    empty[1] = False
    with pytest.raises(ValueError, match=r"masks\[1\] is all background"):
        BackgroundModel().masks(x, empty)
    with pytest.raises(TypeError, match="masks must be a bool tensor"):
        set_background(x, torch.ones(2, 1, 8, 8))
    flat = torch.full((1, 3, 8, 8), 0.5)
    with pytest.raises(
        ValueError, match=r"background=\(0.5, 0.5, 0.5\) ± .*estimated.*leaves no object in images\[0\]"
    ):
        BackgroundModel().masks(flat)
    with pytest.raises(ValueError, match=r"background=\(0.5, 0.5, 0.5\) ± 0.3 \(given\) leaves no object"):
        BackgroundModel(background=(0.5, 0.5, 0.5), tolerance=0.3).masks(flat + 0.1 * torch.rand(1, 3, 8, 8))
    with pytest.raises(ValueError, match=r"background=\(0.1, 0.2\) must hold C=3 values"):
        BackgroundModel(background=(0.1, 0.2)).masks(x)
    with pytest.raises(ValueError, match=r"background=\(0.1, 2.0\) must hold one value in \[0, 1\]"):
        BackgroundModel(background=(0.1, 2.0))
    with pytest.raises(ValueError, match="tolerance=-1 must be positive"):
        BackgroundModel(tolerance=-1)
    with pytest.raises(ValueError, match="border=4 must be less than half the image side"):
        BackgroundModel(border=4).masks(x)
    with pytest.raises(ValueError, match="images must have shape"):
        BackgroundModel().masks(x[0])


def test_seed_masks_replace_the_threshold_in_synthesis() -> None:
    """With the exact masks, synthesis on a masked backdrop render equals synthesis on black
    with the same masks; without masks it is the threshold's (unchanged behaviour)."""
    obj, cam = make_object("superquadric", seed=2), OrthographicCamera(32)
    opts = SynthesisOptions(elevation=0.0, extent=True, silhouette=True, flow_options={}, background=1e-3)
    black = [render(obj, t, cam) for t in (0.0, 10.0)]
    seeds = torch.stack([r.image for r in black])
    masks = torch.stack([r.mask for r in black])
    on = [render(obj, t, cam, backdrop=Backdrop()) for t in (0.0, 10.0)]
    masked = torch.stack([set_background(r.image[None], r.mask[None, None])[0, :1] for r in on])
    assert torch.equal(masked, seeds)
    a = synthesize_views(masked, 10.0, [-5.0, 5.0], opts, masks=masks).views
    b = synthesize_views(seeds, 10.0, [-5.0, 5.0], opts, masks=masks).views
    assert torch.equal(a, b)
    threshold = synthesize_views(seeds, 10.0, [-5.0, 5.0], opts, masks=seeds[:, 0] > 1e-3).views
    assert torch.equal(threshold, synthesize_views(seeds, 10.0, [-5.0, 5.0], opts).views)
    with pytest.raises(ValueError, match=r"masks must have shape \(V, H, W\) = \(2, 32, 32\)"):
        synthesize_views(seeds, 10.0, [5.0], opts, masks=masks[:, None])


def _save(path: Path, arr: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    skimage.io.imsave(path, arr, check_contrast=False)
    return path


def _to_u8(image: torch.Tensor) -> np.ndarray:
    return (image.permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)


def test_view_dataset_masks_the_background(tmp_path: Path) -> None:
    """Views with a mask file, with none (estimated) and with an all-background mask."""
    cam, rows = OrthographicCamera(40), ["path,object,azimuth,mask"]
    renders = {}
    for k, az in enumerate((0, 20)):
        r = render(make_object("cylinder"), float(az), cam, backdrop=Backdrop(seed=k))
        renders[az] = r
        _save(tmp_path / f"v{az}.png", _to_u8(r.image))
        mask_path = _save(tmp_path / f"m{az}.png", r.mask.numpy().astype(np.uint8) * 255)
        rows.append(f"v{az}.png,cyl,{az},{mask_path.name if az == 0 else ''}")
    (tmp_path / "views.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    manifest = ViewManifest.from_csv(tmp_path / "views.csv")
    plain = ViewDataset(manifest)
    assert not torch.equal(
        plain[0]["image"], set_background(plain[0]["image"][None], plain[0]["mask"][None])[0]
    )
    data = ViewDataset(manifest, background=BackgroundModel())
    for i, az in enumerate((0, 20)):
        item = data[i]
        assert _iou(item["mask"][0], renders[az].mask) > 0.97
        assert torch.equal(
            item["image"][:, ~item["mask"][0]], torch.zeros_like(item["image"][:, ~item["mask"][0]])
        )
    assert torch.equal(data[0]["mask"][0], renders[0].mask)  # the mask file decides
    _save(tmp_path / "m0.png", np.zeros((40, 40), np.uint8))
    with pytest.raises(ValueError, match=r"views.csv line 2: .*v0.png: masks\[0\] is all background"):
        data[0]
