"""A model file as the commands and the Python API use it: a recognizer and how its
images are to be prepared.

:func:`load_model` reads a file written by :func:`~torch_eigview.io.checkpoint.save_recognizer`
(``eigview fit``, ``eigview coil --save``; its checksum verified) and returns a
:class:`Model`: the recognizer, the :class:`~torch_eigview.io.preprocessing.Preprocessing`
its images need (size, channels, background rule, unit norm) and the file's metadata.
``eigview evaluate``, ``predict --model`` and ``export`` all load through it, so a file
means the same to each of them.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from torch_eigview.io.checkpoint import load_recognizer
from torch_eigview.io.images import check_regular_file
from torch_eigview.io.preprocessing import Preprocessing, prepare_file
from torch_eigview.nn.recognition import NearestNeighborRecognizer, Recognition

__all__ = ["Model", "load_model", "model_preprocessing"]

# The writers that always record the preprocessing ("command" in the metadata).
_RECORDING = {"fit": "eigview fit", "python": "FewViewEigenspace.save"}


@dataclass(frozen=True)
class Model:
    """A loaded model file.

    Attributes:
        recognizer: the nearest-neighbour recognizer (projection layer and gallery).
        preprocessing: how an image becomes the recognizer's (C, H, W) input.
        metadata: the JSON metadata the file was written with (the command that wrote it,
            the seed azimuths, the gallery range, …).
        path: the file it was read from.
    """

    recognizer: NearestNeighborRecognizer
    preprocessing: Preprocessing
    metadata: dict[str, Any]
    path: str

    def label_table(self) -> dict[str, int]:
        """Object name -> label value: the recognizer's label names (one per distinct
        label, in sorted label order), or each label's own number (``eigview coil --save``:
        COIL ids)."""
        distinct = sorted(set(self.recognizer.labels.tolist()))
        names = self.recognizer.label_names or [str(label) for label in distinct]
        return dict(zip(names, distinct, strict=True))

    def predict_files(
        self, paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], *, reject: bool = False
    ) -> Recognition:
        """Recognizes image files read through the recorded preprocessing
        (:func:`~torch_eigview.io.preprocessing.prepare_file`, as ``eigview predict`` reads
        them): the labels, poses and distances of ``eigview predict --model``.

        Returns:
            The recognizer's :class:`~torch_eigview.nn.recognition.Recognition`: (B,)
            labels (``label_table()`` maps names to them), poses, distances, gallery indices
            and, with ``reject``, ``known``.
        """
        import numpy as np
        import torch

        files = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
        codes = self.recognizer.codes
        arrays = [prepare_file(path, self.preprocessing) for path in files]
        shape = self.preprocessing.image_shape
        stacked = np.stack(arrays) if arrays else np.zeros((0, *shape), np.float32)
        images = torch.from_numpy(stacked).to(dtype=codes.dtype, device=codes.device)
        with torch.no_grad():
            return self.recognizer.predict(images, reject=reject)


def model_preprocessing(
    recognizer: NearestNeighborRecognizer, metadata: dict[str, Any], source: str
) -> Preprocessing:
    """The preprocessing recorded in a model's metadata (``eigview fit`` writes one).

    A model without one (``eigview coil --save``) takes images of its own (C, H, W) as
    read, with the black background of the data it came from.

    Raises:
        ValueError: a recorded preprocessing that is damaged or disagrees with the
            eigenspace's image shape, or no record for a model whose images are not gray
            or RGB; the message starts with ``source``.
    """
    shape = recognizer.projection.image_shape
    if "preprocessing" in metadata:
        prep = Preprocessing.from_json(metadata["preprocessing"], source)
        if shape is not None and prep.image_shape != tuple(shape):
            raise ValueError(
                f"{source}: its preprocessing gives {prep.image_shape}, its eigenspace takes {shape}"
            )
        unit_norm = bool(recognizer.projection.unit_norm)
        if prep.unit_norm != unit_norm:
            raise ValueError(
                f"{source}: its preprocessing record says unit_norm={prep.unit_norm}, its eigenspace "
                f"unit_norm={unit_norm}: the record must describe the projection"
            )
        return prep
    if metadata.get("command") in _RECORDING:
        raise ValueError(
            f"{source} was written by {_RECORDING[metadata['command']]} but has no 'preprocessing' "
            "record in its metadata (a field such a file always holds): the file was edited or "
            "damaged; fit it again"
        )
    if shape is None or shape[0] not in (1, 3):
        raise ValueError(
            f"{source} records no preprocessing and takes images {shape}: write it with eigview fit"
        )
    return Preprocessing((shape[1], shape[2]), shape[0], unit_norm=bool(recognizer.projection.unit_norm))


def load_model(path: str | os.PathLike[str]) -> Model:
    """Reads a model file: its recognizer (checksum verified), preprocessing and metadata.

    Raises:
        ValueError: not a regular file, missing, damaged, not a recognizer's, or with a
            damaged preprocessing record; the message names the file.
    """
    text = os.fspath(path)
    check_regular_file(text, "model")
    recognizer, metadata = load_recognizer(text)
    return Model(recognizer, model_preprocessing(recognizer, metadata, f"model {text}"), metadata, text)
