"""What the frozen projection layers share: views in, coordinates out, settings as extra state.

:class:`FrozenProjection` is the base of ``EigenProjection`` and ``KernelProjection``. It
holds the ``unit_norm`` flag and the optional ``image_shape`` (saved in ``state_dict`` as
extra state, since they are not tensors), the ``eigenvalues`` buffer, the input check and
``prepare``. Each subclass registers its own buffers and defines ``in_features``,
``n_components`` and ``_project``.

Both layers are built either from sizes, with zero buffers for ``load_state_dict`` to fill
(as torchvision's ``FrozenBatchNorm2d``), or from tensors through the named classmethod
``from_tensors``; :func:`is_size` tells the two call forms apart and :func:`check_sizes`
checks the first. Tensors passed to the constructor itself still work, with a
``DeprecationWarning`` (:func:`warn_tensor_form`).
"""

from __future__ import annotations

import contextlib
import numbers
import warnings
from collections.abc import Iterator, Sequence
from contextvars import ContextVar
from typing import Any, ClassVar

import torch
from torch import nn

from torch_eigview.check import (
    check_finite,
    check_float_tensor,
    check_image_shape,
    check_int,
    check_view_input,
)
from torch_eigview.nn.functional import unit_rows

__all__ = [
    "FrozenProjection",
    "check_all_finite",
    "check_eigenvalues",
    "check_same_dtype",
    "check_sizes",
    "from_tensors_call",
    "is_size",
    "warn_tensor_form",
]

# Set while a ``from_tensors`` classmethod builds its layer through the constructor.
_FROM_TENSORS: ContextVar[bool] = ContextVar("torch_eigview_from_tensors", default=False)


@contextlib.contextmanager
def from_tensors_call() -> Iterator[None]:
    """Within it, the constructor's tensor form is ``from_tensors``'s, not deprecated."""
    token = _FROM_TENSORS.set(True)
    try:
        yield
    finally:
        _FROM_TENSORS.reset(token)


def warn_tensor_form(cls: str, arguments: str) -> None:
    """Warns that tensors were passed to the constructor ``cls(arguments)``, outside
    :func:`from_tensors_call`: the constructor takes sizes, ``cls.from_tensors`` tensors."""
    if not _FROM_TENSORS.get():
        warnings.warn(
            f"{cls}({arguments}) with tensors is deprecated: build the layer from tensors with "
            f"{cls}.from_tensors({arguments}); the constructor takes sizes",
            DeprecationWarning,
            stacklevel=3,
        )


# ``nn.Module`` saves ``get_extra_state()`` under ``prefix + "_extra_state"``.
_EXTRA_STATE_KEY = "_extra_state"


def is_size(value: object) -> bool:
    """Whether a constructor's first argument is a size (an integer, the sizes form) rather
    than a tensor (the tensor form)."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def check_sizes(sizes: Sequence[tuple[object, str]], eigenvalues: object) -> list[int]:
    """The named sizes of the sizes form, each an integer >= 1.

    Raises:
        TypeError: a size is not an integer, or ``eigenvalues`` are given (they come with
            the tensors, or from the loaded ``state_dict``).
        ValueError: a size is below 1.
    """
    if eigenvalues is not None:
        raise TypeError(
            "eigenvalues must be None when the layer is built from sizes (they come from the "
            f"loaded state_dict); got {type(eigenvalues).__name__}: pass tensors to from_tensors instead"
        )
    return [check_int(value, name, minimum=1) for value, name in sizes]


def check_eigenvalues(
    eigenvalues: torch.Tensor | None, n_components: int, reference: torch.Tensor
) -> torch.Tensor:
    """The (k,) ``eigenvalues`` checked for type and shape, or an empty (0,) tensor of
    ``reference``'s dtype when they are None ("unknown"; the projection never uses them)."""
    if eigenvalues is None:
        return reference.new_empty(0)
    check_float_tensor(eigenvalues, "eigenvalues")
    if tuple(eigenvalues.shape) != (n_components,):
        raise ValueError(
            f"eigenvalues must have shape ({n_components},), one per component, got {tuple(eigenvalues.shape)}"
        )
    return eigenvalues


def check_same_dtype(
    tensors: Sequence[tuple[torch.Tensor, str]], reference: torch.Tensor, reference_name: str
) -> None:
    """Raises TypeError when a named tensor's dtype differs from ``reference``'s."""
    for tensor, name in tensors:
        if tensor.dtype != reference.dtype:
            raise TypeError(
                f"{name} must have dtype {reference.dtype} like {reference_name}, got {tensor.dtype}"
            )


def check_all_finite(tensors: Sequence[tuple[torch.Tensor, str]]) -> None:
    """Raises ValueError at the first named tensor that holds NaN or infinite values."""
    for tensor, name in tensors:
        check_finite(tensor, name)


class FrozenProjection(nn.Module):
    """Base of the frozen projection layers: (B, C, H, W) or (B, N) views → (B, k) coordinates.

    Args:
        unit_norm: divide each input view by its L2 norm before projecting.

    Raises:
        TypeError: ``unit_norm`` is not a bool.
    """

    eigenvalues: torch.Tensor
    image_shape: tuple[int, int, int] | None
    # Keys ``set_extra_state`` requires; "unit_norm" may be missing (it then reads False).
    _STATE_KEYS: ClassVar[tuple[str, ...]] = ("image_shape",)

    def __init__(self, unit_norm: bool) -> None:
        super().__init__()
        if not isinstance(unit_norm, bool):
            raise TypeError(f"unit_norm must be a bool, got {type(unit_norm).__name__}")
        self.unit_norm = unit_norm

    @property
    def in_features(self) -> int:
        """N, the number of values in one view."""
        raise NotImplementedError

    @property
    def n_components(self) -> int:
        """k, the dimension of the eigenspace."""
        raise NotImplementedError

    def _register_eigenvalues(self, eigenvalues: torch.Tensor, device: torch.device) -> None:
        # A copy, so that later in-place edits of the caller's tensor cannot reach the layer.
        self.register_buffer("eigenvalues", eigenvalues.detach().clone().to(device))

    def _convert(self, dtype: torch.dtype | None, device: torch.device | str | None) -> None:
        """Moves the buffers to the constructor's ``dtype`` and ``device`` when given."""
        if dtype is not None or device is not None:
            self.to(device=device, dtype=dtype)

    def _check_views(self, x: torch.Tensor) -> None:
        # Every floating buffer has one dtype (checked at construction; .to() casts them together).
        check_view_input(x, self.in_features, self.image_shape, self.eigenvalues.dtype)

    def prepare(self, x: torch.Tensor) -> torch.Tensor:
        """(B, ...) views → (B, N) vectors as the eigenspace sees them: in the buffers' dtype,
        flattened, unit norm if set."""
        dtype = self.eigenvalues.dtype
        # A drop-in layer takes what the layers before it give: a float64 batch, or under
        # autocast a bfloat16 or float16 one. The unit norm is taken in the buffers' dtype
        # (a bfloat16 sum of squares keeps 3 digits); autocast still runs the matrix
        # product in its own dtype. The cast is static (dtypes, not data), so an exported
        # or compiled graph has a Cast node only where the dtypes differ.
        if x.dtype != dtype:
            x = x.to(dtype)
        return unit_rows(x) if self.unit_norm else x.flatten(1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Projects a batch of views onto the eigenspace.

        Args:
            x: (B, C, H, W) or (B, N) views on the buffers' device, of any floating dtype:
                they are cast to the buffers' dtype first (autocast bfloat16 or float16
                batches and float64 ones work as they are).

        Returns:
            (B, k) eigenspace coordinates in the buffers' dtype (under autocast, in
            autocast's dtype). Differentiable with respect to ``x``.

        Raises:
            ValueError: ``x`` does not have one of the accepted shapes.
            TypeError: ``x`` is not a floating tensor (scale integer images to [0, 1] first).
        """
        self._check_views(x)
        return self._project(self.prepare(x))

    def _project(self, v: torch.Tensor) -> torch.Tensor:
        """(B, N) prepared views → (B, k) coordinates."""
        raise NotImplementedError

    def get_extra_state(self) -> dict[str, Any]:
        """Saves ``image_shape`` and ``unit_norm`` in ``state_dict`` (not tensors, so not buffers)."""
        return {"image_shape": self.image_shape, "unit_norm": self.unit_norm}

    def set_extra_state(self, state: Any) -> None:
        """Restores what ``get_extra_state`` saved, checking ``image_shape`` against ``in_features``."""
        keys = self._STATE_KEYS
        if not isinstance(state, dict) or not set(keys) <= set(state):
            what = f"key {keys[0]!r}" if len(keys) == 1 else f"keys {sorted(keys)}"
            raise ValueError(f"extra state must be a dict with {what}, got {state!r}")
        self._restore(state)

    def _save_to_state_dict(self, destination: dict[str, Any], prefix: str, keep_vars: bool) -> None:
        super()._save_to_state_dict(destination, prefix, keep_vars)
        if torch.onnx.is_in_onnx_export():
            # The TorchScript exporter (torch.onnx.export's default before torch 2.9) calls
            # .detach() on every state_dict value (torch.jit._unique_state_dict), and the
            # settings are not tensors; the graph holds what they decide as constants anyway.
            destination.pop(prefix + _EXTRA_STATE_KEY, None)

    def _load_from_state_dict(self, state_dict: dict[str, Any], prefix: str, *args: Any) -> None:
        # Eigenvalues are optional: (k,) when known, (0,) when not. A layer built from sizes
        # cannot know which the saved one had, so its buffer takes either shape.
        incoming = state_dict.get(prefix + "eigenvalues")
        if isinstance(incoming, torch.Tensor) and tuple(incoming.shape) in {(0,), (self.n_components,)}:
            self.eigenvalues = self.eigenvalues.new_empty(incoming.shape)
        super()._load_from_state_dict(state_dict, prefix, *args)

    def _restore(self, state: dict[str, Any]) -> None:
        """Sets the attributes from a checked extra state; subclasses restore theirs first."""
        self.image_shape = check_image_shape(state["image_shape"], self.in_features, "image_shape")
        self.unit_norm = bool(state.get("unit_norm", False))

    def _describe(self) -> str:
        """The sizes and settings ``extra_repr`` starts with."""
        return f"in_features={self.in_features}, n_components={self.n_components}"

    def extra_repr(self) -> str:
        text = self._describe()
        if self.image_shape is not None:
            text += f", image_shape={self.image_shape}"
        if self.unit_norm:
            text += ", unit_norm=True"
        return text
