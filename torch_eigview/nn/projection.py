"""The frozen PCA projection layer: views to eigenspace coordinates and back.

``EigenProjection`` holds what ``Eigenspace.fit`` learned (the mean view and the
eigenvectors) as buffers, so ``.to()``, ``.double()``, ``state_dict``, pickling and ONNX
export treat them as constants. Its ``forward`` is a subtraction and a matrix product:
nothing data-dependent, nothing solved at inference time.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from torch_eigview.check import (
    check_finite,
    check_float_tensor,
    check_image_shape,
    check_ndim,
    check_view_input,
)
from torch_eigview.nn.functional import unit_rows

__all__ = ["EigenProjection"]


class EigenProjection(nn.Module):
    """Projects views onto a frozen eigenspace: ``z = (vec(x) - mean) @ components.T``.

    All state lives in persistent buffers (``mean``, ``components``, ``eigenvalues``);
    the module has no parameters. Inputs must have the buffers' dtype: convert the module
    with ``.to(dtype)`` or ``.double()`` rather than relying on implicit casts.

    Args:
        mean: (N,) the mean view, N = C*H*W (row-major flatten of (C, H, W)).
        components: (k, N) orthonormal eigenvectors, one per row.
        eigenvalues: (k,) eigenvalues of the centred scatter matrix, as in
            ``Eigenspace.eigenvalues_``. Optional; when omitted the buffer is an empty
            (0,) tensor, meaning "unknown" (the projection never uses it).
        image_shape: (C, H, W) of a view, or None. With it, ``reconstruct`` returns images.
            It is saved in ``state_dict`` as extra state, so loading restores it.
        unit_norm: divide each input view by its L2 norm before projecting (the brightness
            normalization of Murase and Nayar's appearance eigenspaces); the eigenspace
            must then have been fitted on unit-norm views. Saved as extra state too.

    Raises:
        TypeError: a tensor argument is not a floating tensor, or the dtypes differ.
        ValueError: shapes are inconsistent, values are not finite, or ``image_shape``
            does not multiply to N.

    Example:
        >>> m = EigenProjection(torch.zeros(6), torch.eye(6)[:2], image_shape=(1, 2, 3))
        >>> m(torch.ones(4, 1, 2, 3)).shape
        torch.Size([4, 2])
    """

    mean: torch.Tensor
    components: torch.Tensor
    eigenvalues: torch.Tensor

    def __init__(
        self,
        mean: torch.Tensor,
        components: torch.Tensor,
        eigenvalues: torch.Tensor | None = None,
        image_shape: tuple[int, int, int] | None = None,
        unit_norm: bool = False,
    ) -> None:
        super().__init__()
        if not isinstance(unit_norm, bool):
            raise TypeError(f"unit_norm must be a bool, got {type(unit_norm).__name__}")
        self.unit_norm = unit_norm
        check_float_tensor(mean, "mean")
        check_float_tensor(components, "components")
        check_ndim(mean, "mean", (1,), "(N,)")
        check_ndim(components, "components", (2,), "(k, N)")
        n_components, n_features = components.shape
        if n_components < 1 or n_features < 1:
            raise ValueError(f"components must have shape (k, N), k, N >= 1, got {tuple(components.shape)}")
        if mean.shape[0] != n_features:
            raise ValueError(
                f"mean must have shape ({n_features},) to match components of shape "
                f"{tuple(components.shape)}, got {tuple(mean.shape)}"
            )
        if components.dtype != mean.dtype:
            raise TypeError(f"components must have dtype {mean.dtype} like mean, got {components.dtype}")
        if eigenvalues is None:
            eigenvalues = mean.new_empty(0)
        else:
            check_float_tensor(eigenvalues, "eigenvalues")
            if tuple(eigenvalues.shape) != (n_components,):
                raise ValueError(
                    f"eigenvalues must have shape ({n_components},), one per component, "
                    f"got {tuple(eigenvalues.shape)}"
                )
            if eigenvalues.dtype != mean.dtype:
                raise TypeError(
                    f"eigenvalues must have dtype {mean.dtype} like mean, got {eigenvalues.dtype}"
                )
        for tensor, name in ((mean, "mean"), (components, "components"), (eigenvalues, "eigenvalues")):
            check_finite(tensor, name)
        self.image_shape = check_image_shape(image_shape, n_features, "image_shape")
        # Copies, so that later in-place edits of the caller's tensors cannot reach the layer.
        self.register_buffer("mean", mean.detach().clone())
        self.register_buffer("components", components.detach().clone())
        self.register_buffer("eigenvalues", eigenvalues.detach().clone().to(components.device))

    @property
    def in_features(self) -> int:
        """N, the number of values in one view."""
        return self.components.shape[1]

    @property
    def n_components(self) -> int:
        """k, the dimension of the eigenspace."""
        return self.components.shape[0]

    def _check_views(self, x: torch.Tensor) -> None:
        check_view_input(x, self.in_features, self.image_shape, self.mean.dtype)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Projects a batch of views onto the eigenspace.

        Args:
            x: (B, C, H, W) or (B, N) views, with the buffers' dtype and device.

        Returns:
            (B, k) eigenspace coordinates. Differentiable with respect to ``x``.

        Raises:
            ValueError: ``x`` does not have one of the accepted shapes.
            TypeError: ``x`` is not a tensor of the buffers' dtype.
        """
        self._check_views(x)
        return (self.prepare(x) - self.mean) @ self.components.T

    def prepare(self, x: torch.Tensor) -> torch.Tensor:
        """(B, ...) views → (B, N) vectors as the eigenspace sees them (flattened, unit norm if set)."""
        return unit_rows(x) if self.unit_norm else x.flatten(1)

    def reconstruct(self, z: torch.Tensor) -> torch.Tensor:
        """Maps eigenspace coordinates back to views: ``z @ components + mean``.

        Args:
            z: (B, k) coordinates, with the buffers' dtype.

        Returns:
            (B, C, H, W) when ``image_shape`` is known, else (B, N).

        Raises:
            ValueError: ``z`` is not (B, k).
            TypeError: ``z`` is not a tensor of the buffers' dtype.
        """
        if not isinstance(z, torch.Tensor):
            raise TypeError(f"z must be a torch.Tensor, got {type(z).__name__}")
        if z.ndim != 2 or z.shape[1] != self.n_components:
            raise ValueError(f"z must have shape (B, {self.n_components}), got shape {tuple(z.shape)}")
        if z.dtype != self.mean.dtype:
            raise TypeError(f"z must have the dtype of the buffers ({self.mean.dtype}), got {z.dtype}")
        views = z @ self.components + self.mean
        if self.image_shape is None:
            return views
        return views.unflatten(1, self.image_shape)

    def get_extra_state(self) -> dict[str, Any]:
        """Saves ``image_shape`` in ``state_dict`` (it is not a tensor, so not a buffer)."""
        return {"image_shape": self.image_shape, "unit_norm": self.unit_norm}

    def set_extra_state(self, state: Any) -> None:
        """Restores ``image_shape`` from ``state_dict``, checking it against ``in_features``."""
        if not isinstance(state, dict) or "image_shape" not in state:
            raise ValueError(f"extra state must be a dict with key 'image_shape', got {state!r}")
        self.image_shape = check_image_shape(state["image_shape"], self.in_features, "image_shape")
        self.unit_norm = bool(state.get("unit_norm", False))

    def extra_repr(self) -> str:
        text = f"in_features={self.in_features}, n_components={self.n_components}"
        if self.image_shape is not None:
            text += f", image_shape={self.image_shape}"
        if self.unit_norm:
            text += ", unit_norm=True"
        return text
