"""The frozen PCA projection layer: views to eigenspace coordinates and back.

``EigenProjection`` holds what ``Eigenspace.fit`` learned (the mean view and the
eigenvectors) as buffers, so ``.to()``, ``.double()``, ``state_dict``, pickling and ONNX
export treat them as constants. Its ``forward`` is a subtraction and a matrix product:
nothing data-dependent, nothing solved at inference time.
"""

from __future__ import annotations

import torch

from torch_eigview.check import check_float_tensor, check_image_shape, check_ndim
from torch_eigview.nn._frozen import FrozenProjection, check_all_finite, check_eigenvalues, check_same_dtype

__all__ = ["EigenProjection"]


class EigenProjection(FrozenProjection):
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

    def __init__(
        self,
        mean: torch.Tensor,
        components: torch.Tensor,
        eigenvalues: torch.Tensor | None = None,
        image_shape: tuple[int, int, int] | None = None,
        unit_norm: bool = False,
    ) -> None:
        super().__init__(unit_norm)
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
        check_same_dtype([(components, "components")], mean, "mean")
        eigenvalues = check_eigenvalues(eigenvalues, n_components, mean)
        check_same_dtype([(eigenvalues, "eigenvalues")], mean, "mean")
        check_all_finite([(mean, "mean"), (components, "components"), (eigenvalues, "eigenvalues")])
        self.image_shape = check_image_shape(image_shape, n_features, "image_shape")
        # Copies, so that later in-place edits of the caller's tensors cannot reach the layer.
        self.register_buffer("mean", mean.detach().clone())
        self.register_buffer("components", components.detach().clone())
        self._register_eigenvalues(eigenvalues, components.device)

    @property
    def in_features(self) -> int:
        """N, the number of values in one view."""
        return self.components.shape[1]

    @property
    def n_components(self) -> int:
        """k, the dimension of the eigenspace."""
        return self.components.shape[0]

    def _project(self, v: torch.Tensor) -> torch.Tensor:
        """(B, N) prepared views → (B, k) coordinates: centre, then project."""
        return (v - self.mean) @ self.components.T

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
