"""Warping: target→source maps, the view-warp modules (orthographic/affine and
perspective), the random turntable rotation augmentation, size normalization and the
sparse G·C operator (Eqs. 3–6).
"""

from __future__ import annotations

from torch_eigview.warp.augmentation import RandomTurntableRotation
from torch_eigview.warp.base import BLENDS
from torch_eigview.warp.maps import WarpMaps
from torch_eigview.warp.normalize import foreground_mask, normalize_extent
from torch_eigview.warp.novel_view import NovelViewWarp
from torch_eigview.warp.operator import SparseViewOperator
from torch_eigview.warp.perspective import PerspectiveWarp, turntable_pose
from torch_eigview.warp.raster import invert_map_2d

__all__ = [
    "BLENDS",
    "NovelViewWarp",
    "PerspectiveWarp",
    "RandomTurntableRotation",
    "SparseViewOperator",
    "WarpMaps",
    "foreground_mask",
    "invert_map_2d",
    "normalize_extent",
    "turntable_pose",
]
