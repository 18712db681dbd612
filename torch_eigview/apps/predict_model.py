"""``eigview predict --model model.pt``: a model file in torch, with ``eigview predict``'s interface.

The images go through the model's recorded preprocessing as ``eigview predict --onnx``
and :meth:`~torch_eigview.io.model.Model.predict_files` read them
(:func:`~torch_eigview.io.preprocessing.prepare_file`), so a file gives the same answer in
either runtime and in Python.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import torch

from torch_eigview.apps.device_option import resolve_device
from torch_eigview.apps.prediction import Prediction
from torch_eigview.datasets.background import background_rule
from torch_eigview.io.model import load_model
from torch_eigview.io.onnx_metadata import OnnxModelInfo
from torch_eigview.io.preprocessing import prepare_file

__all__ = ["ModelRecognizer"]


class ModelRecognizer:
    """A model file of ``eigview fit`` (or ``eigview coil --save``) for ``eigview predict``.

    Args:
        path: the model file; its checksum is verified on load.
        device: where the projection and the search run (``--device``: ``cpu``, ``cuda``,
            ``cuda:N`` or ``auto``); the images are read on the CPU and moved there.

    Attributes:
        info: what the model takes and answers, as an exported graph's metadata would say.

    Raises:
        ValueError: the file is missing, damaged or not a recognizer's, or its
            preprocessing record is; ``device`` names CUDA where there is none.
    """

    def __init__(self, path: str | os.PathLike[str], device: str = "cpu") -> None:
        where = resolve_device(device)  # no CUDA: named before the model is read
        model = load_model(path)
        self.path, self.recognizer, self.prep = model.path, model.recognizer.to(where), model.preprocessing
        self.background = background_rule(self.prep.background, self.prep.colour, self.prep.tolerance)
        self._names = {label: name for name, label in model.label_table().items()}
        self.info = OnnxModelInfo(
            kind="recognizer",
            image_shape=self.prep.image_shape,
            n_components=int(self.recognizer.codes.shape[1]),
            unit_norm=self.prep.unit_norm,
            label_names=tuple(self._names.values()),
            module=type(self.recognizer).__name__,
            reject=self.recognizer.rejects,
            preprocessing=self.prep,
        )

    def load(self, path: str) -> np.ndarray:
        """One image as the model's input ``(C, H, W)`` float32, preprocessed as recorded.

        The background (unless the model keeps it) is found from the image's alpha channel,
        else estimated, as ``eigview evaluate`` does for a view without a mask
        (:func:`~torch_eigview.io.preprocessing.prepare_file`).

        Raises:
            ValueError: not a regular file, unreadable, an all-background alpha, or a
                background that leaves no object; the message names it.
        """
        return prepare_file(path, self.prep)

    def predict_rows(self, images: np.ndarray, names: Sequence[str]) -> list[Prediction | str]:
        """Recognizes (B, C, H, W) float32 ``images``; ``names`` are their files."""
        x = torch.from_numpy(images).to(self.recognizer.codes.device, self.recognizer.codes.dtype)
        with torch.no_grad():
            result = self.recognizer.predict(x, reject=self.recognizer.rejects)
        known = [None] * len(names) if result.known is None else result.known.tolist()
        return [
            Prediction(name, self._names[int(label)], float(pose), float(dist), ok)
            for name, label, pose, dist, ok in zip(
                names,
                result.labels.tolist(),
                result.poses.tolist(),
                result.distances.tolist(),
                known,
                strict=True,
            )
        ]
