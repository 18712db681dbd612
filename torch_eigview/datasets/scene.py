"""The synthetic scene: named rendered objects, their camera and a cache of their views.

:class:`SyntheticScene` renders the embedded objects (:data:`~torch_eigview.datasets.shapes.SHAPES`)
with one camera, on the black background or on a coloured, textured backdrop whose
foreground is then set apart as a user's photographs are, and keeps every rendered view,
so that seed, gallery and test views of one object are rendered once (``eigview demo``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from torch_eigview.check import check_choice
from torch_eigview.datasets.backdrop import Backdrop
from torch_eigview.datasets.background import BackgroundModel
from torch_eigview.datasets.cameras import AffineCamera, OrthographicCamera, PerspectiveCamera
from torch_eigview.datasets.renderer import Render, render_many
from torch_eigview.datasets.shapes import SHAPES, SyntheticObject, make_object

__all__ = ["MASKS", "SyntheticScene"]

#: Where the foreground of a view on a backdrop comes from: the renderer's exact masks or
#: a :class:`~torch_eigview.datasets.background.BackgroundModel` estimated from the border.
MASKS = ("given", "estimated")


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
