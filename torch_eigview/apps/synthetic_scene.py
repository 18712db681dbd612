"""The synthetic scene of the paper's Sec. 5.1 experiments: objects, cameras, galleries.

:class:`SyntheticScene` holds the rendered objects and the camera;
:func:`synthetic_gallery` synthesizes an object's views from its rendered seed views with
the camera model's warp (:func:`camera_warp`: Eq. 7, Sec. 4's affine solve or trifocal
transfer) and :func:`synthesis_error` compares them with renders. The options of every
synthetic experiment are :data:`SYNTHETIC_OPTIONS`. :mod:`torch_eigview.apps.demo` runs the
recognition protocol (Fig. 2) on these galleries.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from torch_eigview.check import check_choice
from torch_eigview.datasets import (
    CAMERAS,
    SHAPES,
    AffineCamera,
    OrthographicCamera,
    PerspectiveCamera,
    exact_correspondence,
    exact_correspondence_2d,
    seen_error,
)
from torch_eigview.datasets.backdrop import Backdrop
from torch_eigview.datasets.background import BackgroundModel
from torch_eigview.datasets.renderer import Render, render_many
from torch_eigview.datasets.shapes import SyntheticObject, make_object
from torch_eigview.evaluation.scoring import angle_range
from torch_eigview.geometry.correspondence import Correspondence
from torch_eigview.synthesis import PairGeometry, SynthesisOptions, pair_geometry, pair_of, synthesize_views
from torch_eigview.warp.normalize import seed_foreground
from torch_eigview.warp.novel_view import NovelViewWarp
from torch_eigview.warp.perspective import PerspectiveWarp

__all__ = [
    "CORRESPONDENCES",
    "MASKS",
    "SYNTHETIC_OPTIONS",
    "SyntheticScene",
    "camera_warp",
    "default_camera",
    "synthesis_error",
    "synthetic_gallery",
]

CORRESPONDENCES = ("flow", "exact", "rendered")
#: Where the foreground of a view on a backdrop comes from: the renderer's exact masks or
#: a :class:`~torch_eigview.datasets.background.BackgroundModel` estimated from the border.
MASKS = ("given", "estimated")
# Synthetic renders: no camera tilt and no size normalization (COIL's defaults), and
# scikit-image's own TV-L1 settings (5 warps of 10 iterations; ``flow_options={}``) rather
# than the 3 × 5 speed preset, which is tuned on COIL only: on these smooth textures
# the preset's flow costs up to 4 points of Fig. 2 (α = 30, two views: 94.67 % against 98.67 %).
# Silhouette-aware sampling against the renders' exactly black background (shaded object
# pixels go down to 0.004, below COIL's 0.05 threshold): without it every synthesized
# silhouette pixel mixes in background, the renders' never do.
SYNTHETIC_OPTIONS = SynthesisOptions(
    elevation=0.0, extent=False, flow_options={}, silhouette=True, background=1e-3
)


@dataclass
class SyntheticScene:
    """The objects and the camera of an experiment, with a cache of rendered views.

    Attributes:
        shapes: object names (see :data:`~torch_eigview.datasets.shapes.SHAPES`).
        camera: the camera (orthographic by default; any :func:`default_camera`).
        seed: texture seed of every object.
        backdrop: None for the black background, or the coloured, textured
            :class:`~torch_eigview.datasets.backdrop.Backdrop` the objects are rendered on.
            Each view's foreground (``masks``) then decides its pixels and its background
            is set to 0, as a user's photographs are before synthesis; the objects are
            gray, so the views keep one channel, which holds their intensity exactly.
        masks: with a backdrop, ``"given"`` (the renderer's exact masks) or
            ``"estimated"`` (:class:`~torch_eigview.datasets.background.BackgroundModel`).
    """

    shapes: Sequence[str] = SHAPES
    camera: AffineCamera | PerspectiveCamera = field(default_factory=lambda: OrthographicCamera(64))
    seed: int = 0
    backdrop: Backdrop | None = None
    masks: str = "given"
    _objects: dict[str, SyntheticObject] = field(default_factory=dict, repr=False)
    _cache: dict[tuple[str, float], tuple[torch.Tensor, torch.Tensor]] = field(
        default_factory=dict, repr=False
    )

    def __post_init__(self) -> None:
        if self.backdrop is not None and not isinstance(self.backdrop, Backdrop):
            raise TypeError(f"backdrop must be a Backdrop or None, got {type(self.backdrop).__name__}")
        check_choice(self.masks, "masks", MASKS)

    def object(self, name: str) -> SyntheticObject:
        if name not in self._objects:
            self._objects[name] = make_object(name, self.seed)
        return self._objects[name]

    def _view(self, r: Render) -> tuple[torch.Tensor, torch.Tensor]:
        """The (1, H, W) view and (H, W) foreground of a render, background 0."""
        if self.backdrop is None:
            return r.image, r.mask
        given = r.mask[None, None] if self.masks == "given" else None
        view, mask = BackgroundModel().apply(r.image[None], given)
        return view[0, :1], mask[0, 0]

    def _cached(self, name: str, thetas: Sequence[float]) -> list[tuple[torch.Tensor, torch.Tensor]]:
        keys = [(name, round(float(t), 9)) for t in thetas]
        # The views not rendered yet, each once, in one call (the rays cast for all at once).
        missing: dict[tuple[str, float], float] = {}
        for key, t in zip(keys, thetas, strict=True):
            if key not in self._cache:
                missing.setdefault(key, float(t))  # the first angle of a key, as rendered one by one
        if missing:
            renders = render_many(
                self.object(name), list(missing.values()), self.camera, backdrop=self.backdrop
            )
            for key, r in zip(missing, renders, strict=True):
                self._cache[key] = self._view(r)
        return [self._cache[key] for key in keys]

    def views(self, name: str, thetas: Sequence[float]) -> torch.Tensor:
        """(T, 1, H, W) rendered views of object ``name`` at ``thetas`` (degrees)."""
        return torch.stack([view for view, _ in self._cached(name, thetas)])

    def foreground(self, name: str, thetas: Sequence[float]) -> torch.Tensor | None:
        """(T, H, W) bool foreground of the views at ``thetas``: None without a backdrop
        (the synthesis then thresholds the black background, as before)."""
        if self.backdrop is None:
            return None
        return torch.stack([mask for _, mask in self._cached(name, thetas)])


def default_camera(name: str, size: int = 64) -> AffineCamera | PerspectiveCamera:
    """The camera of each model in ``eigview synth``.

    ``"orthographic"``: the paper's (:func:`~torch_eigview.datasets.cameras.OrthographicCamera`).
    ``"affine"``: anisotropic scale (0.9 and 1.05 of the orthographic one), a start angle
    (x also sees 0.15·Z) and the rotation axis 2 pixels left of the centre column.
    ``"perspective"``: a pinhole at 4 object radii from the axis (the object spans about
    ±15° of the field of view).
    """
    if name == "orthographic":
        return OrthographicCamera(size)
    if name == "affine":
        s = 0.45 * size
        return AffineCamera(
            ((0.9 * s, 0.0, 0.15 * s), (0.0, -1.05 * s, 0.0)),
            size,
            offset=((size - 1) / 2 - 2, (size - 1) / 2 + 1),
        )
    if name == "perspective":
        return PerspectiveCamera(size, distance=4.0)
    raise ValueError(f"unknown camera name={name!r}; known cameras: {', '.join(CAMERAS)}")


def _is_plain_orthographic(camera: AffineCamera | PerspectiveCamera) -> bool:
    if not isinstance(camera, AffineCamera):
        return False
    ortho = OrthographicCamera((camera.height, camera.width), float(camera.P[0, 0]))
    return bool(torch.equal(camera.P, ortho.P))


def camera_warp(
    camera: AffineCamera | PerspectiveCamera, alpha: float, blend: str = "linear"
) -> NovelViewWarp | PerspectiveWarp:
    """The warp of a camera model: Eq. 7 (orthographic), Sec. 4's affine solve or trifocal
    transfer; ``blend`` as :class:`~torch_eigview.warp.novel_view.NovelViewWarp`'s."""
    if isinstance(camera, PerspectiveCamera):
        return PerspectiveWarp(alpha, camera._k, camera.distance, blend=blend)
    if _is_plain_orthographic(camera):
        return NovelViewWarp(alpha, blend=blend)
    return NovelViewWarp(alpha, camera=camera.P, blend=blend)


def _pair_correspondence(
    scene: SyntheticScene, name: str, alpha: float, theta_1: float, correspondences: str
) -> Correspondence:
    if correspondences == "exact":
        obj = scene.object(name)
        if isinstance(scene.camera, PerspectiveCamera):
            return exact_correspondence_2d(obj, alpha, scene.camera, theta_1=theta_1)
        return exact_correspondence(obj, alpha, scene.camera, theta_1=theta_1)
    seeds = scene.views(name, [theta_1, theta_1 + alpha])
    return pair_geometry(seeds, alpha, SYNTHETIC_OPTIONS)[0].correspondence


def _camera_gallery(
    scene: SyntheticScene,
    name: str,
    alpha: float,
    first: float,
    n_views: int,
    thetas: list[float],
    correspondences: str,
) -> torch.Tensor:
    """Views at ``thetas`` for an affine or perspective camera, each angle from the seed
    pair :func:`~torch_eigview.synthesis.pair_of` routes it to."""
    warp = camera_warp(scene.camera, alpha, SYNTHETIC_OPTIONS.blend)
    rel = torch.tensor(thetas, dtype=torch.float64) - first
    pair = pair_of(rel, alpha, n_views)
    out: list[torch.Tensor | None] = [None] * len(thetas)
    for n in range(n_views - 1):
        sel = (pair == n).nonzero().flatten().tolist()
        if not sel:
            continue
        seed_angles = [first + n * alpha, first + (n + 1) * alpha]
        seeds = scene.views(name, seed_angles)
        corr = _pair_correspondence(scene, name, alpha, first + n * alpha, correspondences)
        opts = SYNTHETIC_OPTIONS
        fg = seed_foreground(seeds, scene.foreground(name, seed_angles), opts.background)
        masks = fg if opts.silhouette else None
        views = warp(
            seeds[0],
            seeds[1],
            correspondence=corr,
            thetas=[float(rel[i]) - n * alpha for i in sel],
            masks=masks,
        )
        for j, i in enumerate(sel):
            out[i] = views[j]
    return torch.stack([v for v in out if v is not None])


def synthesis_error(
    scene: SyntheticScene, name: str, alpha: float, thetas: Sequence[float], correspondences: str = "exact"
) -> list[float]:
    """Per-pixel mean absolute error of views synthesized from seeds 0° and α against renders.

    Over the pixels of the rendered view at θ that both seed views see (the paper's
    "except occluded pixels"); intensities are in [0, 1], so 0.01 is 1%.

    Returns:
        One error per angle in ``thetas``.
    """
    obj = scene.object(name)
    views = _camera_gallery(scene, name, alpha, 0.0, 2, list(thetas), correspondences)
    return [
        seen_error(obj, scene.camera, v, float(t), (0.0, alpha)) for v, t in zip(views, thetas, strict=True)
    ]


def _gallery_angles(
    alpha: float, n_views: int, synth: tuple[float, float, float] | None
) -> tuple[float, list[float]]:
    """The first seed's angle and the gallery's angles (see :func:`synthetic_gallery`)."""
    if n_views not in (2, 3):
        raise ValueError(f"n_views must be 2 or 3, got {n_views}")
    first = 0.0 if n_views == 2 else -alpha
    if synth is None:
        # On the 1° grid of the seeds and test views: half an α each side, rounded up.
        reach = 20.0 if n_views == 2 else 20.0 + math.ceil(abs(alpha) / 2)
        synth = (-reach, reach, 1.0)
    return first, angle_range(*synth, name="synth")


def synthetic_gallery(
    scene: SyntheticScene,
    name: str,
    alpha: float,
    n_views: int = 2,
    synth: tuple[float, float, float] | None = None,
    correspondences: str = "flow",
) -> tuple[torch.Tensor, list[float]]:
    """Synthesized views of one object from its ``n_views`` rendered seed views.

    Two seed views lie at 0° and α, three at −α, 0°, α (the test range's centre in the
    middle). The default ``synth`` is −20°..20° at 1° (the paper's) for two views; for three
    it follows the seeds as in the COIL experiment (:meth:`CoilExperiment.synth_range`): the
    two-view range widened by one α, here ⌈α/2⌉ on each side of the centred seeds,
    −(20 + ⌈α/2⌉)..20 + ⌈α/2⌉ (on the 1° grid of the seeds and test views).

    Args:
        scene: objects and camera.
        name: the object.
        alpha: angle between consecutive seed views, degrees.
        n_views: 2 or 3 seed views.
        synth: (start, stop, step) of the synthesized angles in degrees.
        correspondences: ``"flow"`` (the synthesis options' flow between the seed views, by
            default the guided flow),
            ``"exact"`` (from the renderer's geometry) or ``"rendered"``: no synthesis, the
            *rendered* views at the same angles (the protocol's ceiling: what perfect
            synthesis would give).

    Returns:
        ``(views, thetas)``: (T, 1, H, W) views and their T angles in degrees.
    """
    if correspondences not in CORRESPONDENCES:
        raise ValueError(f"correspondences must be one of {CORRESPONDENCES}, got {correspondences!r}")
    first, thetas = _gallery_angles(alpha, n_views, synth)
    if correspondences == "rendered":
        return scene.views(name, thetas), thetas
    if not _is_plain_orthographic(scene.camera):
        return _camera_gallery(scene, name, alpha, first, n_views, thetas, correspondences), thetas
    seed_angles = [first + n * alpha for n in range(n_views)]
    seeds = scene.views(name, seed_angles)
    geometry = None
    if correspondences == "exact":
        obj, camera = scene.object(name), scene.camera
        assert isinstance(camera, AffineCamera)  # plain orthographic, checked above
        geometry = [
            PairGeometry(exact_correspondence(obj, alpha, camera, theta_1=first + n * alpha), 0.0, 0.0)
            for n in range(n_views - 1)
        ]
    rel = [t - first for t in thetas]
    out = synthesize_views(
        seeds, alpha, rel, SYNTHETIC_OPTIONS, geometry, scene.foreground(name, seed_angles)
    )
    return out.views, thetas
