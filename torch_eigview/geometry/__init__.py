"""Geometry: pose models (orthographic Eq. 7, affine), the trifocal tensor, dense
correspondences and the inversion of 1-D (row) maps.
"""

from __future__ import annotations

from torch_eigview.geometry.correspondence import Correspondence, correspondence_from_disparity
from torch_eigview.geometry.flow import estimate_correspondence
from torch_eigview.geometry.guided_flow import guided_tvl1
from torch_eigview.geometry.pose import (
    AffineCoefficients,
    affine_coefficients,
    estimate_elevation,
    orthographic_coefficients,
    rotation_y,
)
from torch_eigview.geometry.row_maps import fill_row_holes, invert_row_map
from torch_eigview.geometry.row_matcher import match_rows
from torch_eigview.geometry.transfer import epipoles_from_tensor, fundamental_from_tensor, transfer_points
from torch_eigview.geometry.trifocal import (
    novel_view_tensor,
    novel_view_tensor_from_cameras,
    seed_tensor,
    tensor_from_fundamental,
    transform_tensor,
    trifocal_tensor,
)

__all__ = [
    "AffineCoefficients",
    "Correspondence",
    "affine_coefficients",
    "correspondence_from_disparity",
    "epipoles_from_tensor",
    "estimate_correspondence",
    "estimate_elevation",
    "fill_row_holes",
    "fundamental_from_tensor",
    "guided_tvl1",
    "invert_row_map",
    "match_rows",
    "novel_view_tensor",
    "novel_view_tensor_from_cameras",
    "orthographic_coefficients",
    "rotation_y",
    "seed_tensor",
    "tensor_from_fundamental",
    "transfer_points",
    "transform_tensor",
    "trifocal_tensor",
]
