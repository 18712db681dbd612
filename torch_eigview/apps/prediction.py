"""What ``eigview predict`` answers for one image, and how a name from a file is printed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["Prediction", "escape"]


@dataclass(frozen=True)
class Prediction:
    """One recognized image: its file, label name, pose (degrees) and eigenspace distance, and
    whether the model's rejection took it for a known object (None: not asked)."""

    image: str
    label: str
    pose: float
    distance: float
    known: bool | None = None

    def to_json(self) -> dict[str, Any]:
        out = {"image": self.image, "label": self.label, "pose": self.pose, "distance": self.distance}
        if self.known is not None:
            out["known"] = self.known
        return out


def escape(text: str) -> str:
    """``text`` with control and other non-printable characters escaped as ``repr`` would
    (``\\n``, ``\\x1b``, ``\\u2028``), so that a label name or a file name from a file cannot
    forge output lines or send terminal escapes."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
