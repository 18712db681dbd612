"""Evaluation: recognition scored on test views, and the paper's COIL protocol.

:func:`score` recognizes each object's test views with a fitted recognizer and reports the
accuracy, per object and overall, and the pose error of the recognized views.
:class:`CoilExperiment` is the paper's experiment (Sec. 5.2, Fig. 4(b)) on a folder of
COIL-format images: seed views per object, the gallery synthesized by
:class:`~torch_eigview.method.FewViewEigenspace`, every real view over a test range
recognized (``eigview coil``).
"""

from __future__ import annotations

from torch_eigview.evaluation.circle import CircleLayout, circle_layout, grid_step
from torch_eigview.evaluation.coil import CoilExperiment
from torch_eigview.evaluation.coil_result import CoilResult
from torch_eigview.evaluation.scoring import Score, score
from torch_eigview.evaluation.seed_pose import SeedPoses

__all__ = [
    "CircleLayout",
    "CoilExperiment",
    "CoilResult",
    "Score",
    "SeedPoses",
    "circle_layout",
    "grid_step",
    "score",
]
