"""The frozen PCA projection layer: views to eigenspace coordinates and back.

``EigenProjection`` holds what ``Eigenspace.fit`` learned (the mean view and the
eigenvectors) as buffers, so ``.to()``, ``.double()``, ``state_dict``, pickling and ONNX
export treat them as constants. Its ``forward`` is a subtraction and a matrix product:
nothing data-dependent, nothing solved at inference time.
"""

from __future__ import annotations

import torch

from torch_eigview.check import check_float_tensor, check_image_shape, check_ndim
from torch_eigview.nn._frozen import (
    FrozenProjection,
    check_all_finite,
    check_eigenvalues,
    check_same_dtype,
    check_sizes,
    from_tensors_call,
    is_size,
    warn_tensor_form,
)

__all__ = ["EigenProjection"]


class EigenProjection(FrozenProjection):
    """Projects views onto a frozen eigenspace: ``z = (vec(x) - mean) @ components.T``.

    All state lives in persistent buffers (``mean``, ``components``, ``eigenvalues``);
    the module has no parameters. Inputs of any floating dtype are cast to the buffers'
    dtype (float32 unless converted with ``.to(dtype)`` or ``.double()``), so the layer takes
    autocast's bfloat16 or float16 batches, and float64 ones, as they come.

    Built from sizes, as torchvision's ``FrozenBatchNorm2d``, the buffers start as zeros
    (eigenvalues unknown) for ``load_state_dict`` to fill; the saved ``image_shape`` and
    ``unit_norm`` come back with them (extra state), and the saved eigenvalues may be (k,)
    or unknown. :meth:`from_tensors` builds the layer from a fit's tensors. Passing them here
    in place of the sizes, ``EigenProjection(mean, components, ...)``, is deprecated: it does
    the same with a ``DeprecationWarning``.

    Args:
        n_features: N = C*H*W, the number of values in one view (row-major flatten of
            (C, H, W)); or the (N,) mean view (the tensor form).
        n_components: k, the number of eigenvectors; or the (k, N) components (the
            tensor form).
        eigenvalues: tensor form only: (k,) eigenvalues of the centred scatter matrix, as
            in ``Eigenspace.eigenvalues_``, or None ("unknown": an empty (0,) buffer; the
            projection never uses it).
        image_shape: (C, H, W) of a view, or None. With it, ``reconstruct`` returns images.
            It is saved in ``state_dict`` as extra state, so loading restores it.
        unit_norm: divide each input view by its L2 norm before projecting (the brightness
            normalization of Murase and Nayar's appearance eigenspaces); the eigenspace
            must then have been fitted on unit-norm views. Saved as extra state too.
        dtype: dtype of the buffers (default: the tensors', or torch's default dtype for
            sizes); load a float64 layer's ``state_dict`` into a float64 one to keep it exact.
        device: device of the buffers (default: the tensors', or the CPU for sizes).

    Raises:
        TypeError: a size is not an integer; a tensor argument is not a floating tensor,
            or the dtypes differ; eigenvalues given with sizes.
        ValueError: a size is below 1, shapes are inconsistent, values are not finite, or
            ``image_shape`` does not multiply to N.

    Example:
        >>> fitted = EigenProjection.from_tensors(torch.zeros(6), torch.eye(6)[:2], image_shape=(1, 2, 3))
        >>> fitted(torch.ones(4, 1, 2, 3)).shape
        torch.Size([4, 2])
        >>> fresh = EigenProjection(6, 2)
        >>> _ = fresh.load_state_dict(fitted.state_dict())
        >>> fresh
        EigenProjection(in_features=6, n_components=2, image_shape=(1, 2, 3))
    """

    mean: torch.Tensor
    components: torch.Tensor

    def __init__(
        self,
        n_features: int | torch.Tensor,
        n_components: int | torch.Tensor,
        eigenvalues: torch.Tensor | None = None,
        image_shape: tuple[int, int, int] | None = None,
        unit_norm: bool = False,
        *,
        dtype: torch.dtype | None = None,
        device: torch.device | str | None = None,
    ) -> None:
        super().__init__(unit_norm)
        if is_size(n_features):
            n, k = check_sizes([(n_features, "n_features"), (n_components, "n_components")], eigenvalues)
            if k > n:
                raise ValueError(
                    f"n_components={k} must be <= n_features={n}: N values span at most N orthonormal components"
                )
            mean, components = torch.zeros(n), torch.zeros(k, n)
        else:
            warn_tensor_form("EigenProjection", "mean, components, ...")
            mean = check_float_tensor(n_features, "mean")
            components = check_float_tensor(n_components, "components")
        self._register(mean, components, eigenvalues, image_shape)
        self._convert(dtype, device)

    @classmethod
    def from_tensors(
        cls,
        mean: torch.Tensor,
        components: torch.Tensor,
        eigenvalues: torch.Tensor | None = None,
        image_shape: tuple[int, int, int] | None = None,
        unit_norm: bool = False,
        *,
        dtype: torch.dtype | None = None,
        device: torch.device | str | None = None,
    ) -> EigenProjection:
        """The layer holding copies of a fit's tensors.

        Args:
            mean: (N,) the mean view.
            components: (k, N) orthonormal eigenvectors, one per row, of ``mean``'s dtype.
            eigenvalues: optional (k,) eigenvalues (see the class).
            image_shape, unit_norm, dtype, device: as for the class.

        Raises:
            TypeError, ValueError: as for the class.
        """
        mean = check_float_tensor(mean, "mean")
        with from_tensors_call():
            return cls(mean, components, eigenvalues, image_shape, unit_norm, dtype=dtype, device=device)

    def _register(
        self,
        mean: torch.Tensor,
        components: torch.Tensor,
        eigenvalues: torch.Tensor | None,
        image_shape: tuple[int, int, int] | None,
    ) -> None:
        """Checks the tensors against each other and registers copies as buffers."""
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
            z: (B, k) coordinates of any floating dtype (cast to the buffers', as ``forward``
                casts its views).

        Returns:
            (B, C, H, W) when ``image_shape`` is known, else (B, N), in the buffers' dtype.

        Raises:
            ValueError: ``z`` is not (B, k).
            TypeError: ``z`` is not a floating tensor.
        """
        if not isinstance(z, torch.Tensor):
            raise TypeError(f"z must be a torch.Tensor, got {type(z).__name__}")
        if z.ndim != 2 or z.shape[1] != self.n_components:
            raise ValueError(f"z must have shape (B, {self.n_components}), got shape {tuple(z.shape)}")
        if not z.dtype.is_floating_point:
            raise TypeError(
                f"z must have a floating dtype (cast to the buffers' {self.mean.dtype}), got {z.dtype}"
            )
        if z.dtype != self.mean.dtype:
            z = z.to(self.mean.dtype)
        views = z @ self.components + self.mean
        if self.image_shape is None:
            return views
        return views.unflatten(1, self.image_shape)
