"""From a few seed views of one object to its dense set of views (Secs. 3 and 4.1).

The seed views are at 0, α, 2α, …, (m − 1)·α (degrees; α may be negative), or at
0, α_1, α_1 + α_2, … with one positive angle α_n per consecutive pair (Sec. 4.1). Each
consecutive pair n (seeds n and n + 1, 0 <= n <= m − 2) synthesizes the angles of its own
sector, with the pair's own angles as reference, so A is the concatenation
[G1C1 … G(m−1)C(m−1)] of Sec. 4.1 in its direct form. Every synthesized view comes from
exactly one pair (:func:`pair_of`):

- an angle between two seeds, n·α <= θ < (n + 1)·α, from pair n, which interpolates;
- an angle before the first seed, from pair 0, and one at or past the last seed, from
  pair m − 2: the pair nearest in angle extrapolates on each side;
- an interior seed's own angle n·α, from pair n (its first view). Pair n − 1 gives the
  same image there (its second view: the map at a seed's own angle is the identity and
  needs no correspondence; with a tilted camera up to float rounding in the image's
  first and last rows), so the views are continuous across every seam. The pairs are
  not blended (on COIL-20 a cross-fade across the middle seed changed no recognition).

Each pair keeps its own elevation estimate (``elevation="auto"``), from its own flow.

:func:`view_angles` and :func:`seed_pair_poses` go the other way: the angle of a given
view between two seeds, by Eq. 2 over its correspondences with both.
"""

from __future__ import annotations

from torch_eigview.synthesis.circle import Circle, check_overlap, circle_thetas, synthesize_circle
from torch_eigview.synthesis.options import SynthesisOptions
from torch_eigview.synthesis.seed_pairs import (
    MAX_AUTO_ELEVATION,
    ElevationFallbackWarning,
    PairGeometry,
    check_seeds,
    iter_object_geometries,
    object_geometries,
    pair_geometry,
)
from torch_eigview.synthesis.view_pose import seed_pair_poses, view_angles
from torch_eigview.synthesis.views import SynthesizedViews, pair_of, synthesize_views

__all__ = [
    "MAX_AUTO_ELEVATION",
    "Circle",
    "ElevationFallbackWarning",
    "PairGeometry",
    "SynthesisOptions",
    "SynthesizedViews",
    "check_overlap",
    "check_seeds",
    "circle_thetas",
    "iter_object_geometries",
    "object_geometries",
    "pair_geometry",
    "pair_of",
    "seed_pair_poses",
    "synthesize_circle",
    "synthesize_views",
    "view_angles",
]
