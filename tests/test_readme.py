"""The README's commands and Python snippets are the ones that work.

The ```python blocks run as written, in order and in one namespace (a later block may
use an earlier block's names), in a fresh working directory; the test command the README
gives is the one ``.ci/run`` runs.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import torch

from torch_eigview import EigenProjection

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def blocks(language: str) -> list[str]:
    """The fenced code blocks of ``language`` in the README, in order."""
    return re.findall(rf"^```{language}\n(.*?)^```$", README, flags=re.MULTILINE | re.DOTALL)


def test_readme_has_python_blocks() -> None:
    assert blocks("python"), "the README has no ```python block to run"


@pytest.mark.slow
def test_python_blocks_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__readme__"}
    for i, source in enumerate(blocks("python")):
        exec(compile(source, f"README.md python block {i + 1}", "exec"), namespace)
    # The quick start ends with an exportable layer: it knows its image shape.
    layers = [v for v in namespace.values() if isinstance(v, EigenProjection)]
    assert layers, "the README's Python leaves no EigenProjection behind"
    for layer in layers:
        assert layer.image_shape is not None
        assert layer(torch.zeros(2, *layer.image_shape)).shape == (2, layer.n_components)


def test_test_command_is_what_ci_runs() -> None:
    commands = [line for block in blocks("bash") for line in block.splitlines() if "pytest" in line]
    assert len(commands) == 1, f"the README should give one test command, found {commands}"
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert commands[0] in ci, f".ci/run does not run the README's test command {commands[0]!r}"
