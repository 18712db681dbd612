"""A coloured, textured background for the synthetic renders: a backdrop and a ground plane.

The backdrop and the ground stay fixed in the camera frame while the object turns, as a
turntable photograph's cloth and table do. In the camera frame (see
:mod:`torch_eigview.datasets.cameras`): the backdrop is the vertical plane
``zc = −distance`` behind the object; the ground is a slab under it whose top is the
horizontal plane ``yc = ground`` and whose front face is the vertical plane
``zc = front``. An untilted orthographic camera sees the top edge-on, so its rows below
the ground show the front face; a perspective camera looking down onto the plane sees
its top. The object lies above the ground (its bounding sphere's bottom is at −1), so
it hides the background wherever its ray hits it: the render's mask is exact.

Each surface is coloured with a texture of its own, a sum of plane waves in the
surface's two coordinates: as for the objects' textures, smooth enough to be a real
cloth and rich enough that a plain threshold does not separate it from the object.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from torch_eigview.check import check_int, check_number, check_positive

__all__ = ["Backdrop"]

_N_WAVES = 10


def _colour(value: object, name: str) -> tuple[float, float, float]:
    if isinstance(value, str) or not isinstance(value, Sequence) or len(value) != 3:
        raise TypeError(f"{name} must be an (R, G, B) triple, got {value!r}")
    rgb = tuple(check_number(v, name) for v in value)
    if not all(0.0 <= v <= 1.0 for v in rgb):
        raise ValueError(f"{name}={value!r} must hold values in [0, 1]")
    return rgb[0], rgb[1], rgb[2]


@dataclass(frozen=True)
class Backdrop:
    """The background of :func:`~torch_eigview.datasets.renderer.render` with ``backdrop=``.

    Args:
        colour: (R, G, B) mean colour of the backdrop (a blue cloth by default).
        ground_colour: (R, G, B) mean colour of the ground (a wooden table by default).
        texture: relative amplitude of the textures (0 for plain colours).
        distance: the backdrop plane ``zc = −distance``, object units behind the axis.
        ground: height ``yc`` of the ground's top (the objects reach down to −1).
        front: ``zc`` of the ground's front face (in front of the object).
        seed: texture seed.
    """

    colour: Sequence[float] = (0.1, 0.3, 0.7)
    ground_colour: Sequence[float] = (0.7, 0.45, 0.12)
    texture: float = 0.12
    distance: float = 3.0
    ground: float = -1.0
    front: float = 1.5
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "colour", _colour(self.colour, "colour"))
        object.__setattr__(self, "ground_colour", _colour(self.ground_colour, "ground_colour"))
        tex = check_positive(self.texture, "texture", allow_zero=True)
        if tex >= 1:
            raise ValueError(f"texture={self.texture!r} must be below 1 (a relative amplitude)")
        check_positive(self.distance, "distance")
        check_positive(self.front, "front")
        if not math.isfinite(check_number(self.ground, "ground")):
            raise ValueError(f"ground={self.ground!r} must be a finite height")
        check_int(self.seed, "seed")

    def _pattern(self, u: torch.Tensor, v: torch.Tensor, surface: int) -> torch.Tensor:
        """(N,) texture in [−1, 1] at the surface coordinates (u, v) (object units)."""
        gen = torch.Generator().manual_seed(7919 * self.seed + 104_729 * surface + 3)
        angle = 2 * math.pi * torch.rand(_N_WAVES, generator=gen, dtype=torch.float64)
        # Wave numbers 4 to 12 rad per unit: wavelengths of 0.5 to 1.6 object units.
        k = 4.0 + 8.0 * torch.rand(_N_WAVES, generator=gen, dtype=torch.float64)
        phase = 2 * math.pi * torch.rand(_N_WAVES, generator=gen, dtype=torch.float64)
        arg = u[:, None] * (k * angle.cos()) + v[:, None] * (k * angle.sin()) + phase
        return torch.tanh(arg.sin().sum(1) / math.sqrt(_N_WAVES / 2))

    def shade(self, origin: torch.Tensor, direction: torch.Tensor) -> torch.Tensor:
        """The background colour seen along camera-frame rays ``origin + t·direction``.

        Args:
            origin: (N, 3) ray origins in the camera frame.
            direction: (N, 3) ray directions (towards −zc).

        Returns:
            (N, 3) RGB in [0, 1].
        """
        o, d = origin.double(), direction.double()
        dz = d[:, 2].clamp(max=-1e-12)  # every camera looks towards −zc
        t_front = (self.front - o[:, 2]) / dz
        y_front = o[:, 1] + t_front * d[:, 1]
        on_front = y_front < self.ground
        dy = torch.where(d[:, 1] < 0, d[:, 1], torch.full_like(d[:, 1], -1e-300))
        t_top = (self.ground - o[:, 1]) / dy
        z_top = o[:, 2] + t_top * d[:, 2]
        on_top = ~on_front & (d[:, 1] < 0) & (z_top >= -self.distance)
        t_back = (-self.distance - o[:, 2]) / dz
        x_front, x_top, x_back = (o[:, 0] + t * d[:, 0] for t in (t_front, t_top, t_back))
        y_back = o[:, 1] + t_back * d[:, 1]
        pattern = torch.where(
            on_front,
            self._pattern(x_front, y_front, 0),
            torch.where(on_top, self._pattern(x_top, z_top, 1), self._pattern(x_back, y_back, 2)),
        )
        base = torch.where(
            (on_front | on_top)[:, None],
            torch.tensor(self.ground_colour, dtype=torch.float64),
            torch.tensor(self.colour, dtype=torch.float64),
        )
        return (base * (1 + self.texture * pattern[:, None])).clamp(0, 1)
