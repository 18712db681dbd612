"""The synthetic scene on the coloured, textured backdrop: its masks' choices.

The Fig. 2 protocol on the backdrop, with given and estimated masks, is the camera-model
script's (``examples/paper/camera_models.py``; its tests are in ``examples/tests``).
"""

from __future__ import annotations

import pytest

from torch_eigview.datasets import Backdrop, SyntheticScene


def test_scene_rejects_unknown_masks() -> None:
    with pytest.raises(ValueError, match=r"masks='exact' must be one of \('given', 'estimated'\)"):
        SyntheticScene(backdrop=Backdrop(), masks="exact")
