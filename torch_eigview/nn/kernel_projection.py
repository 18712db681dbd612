"""The frozen kernel-PCA projection layer and the kernels it evaluates.

``KernelProjection`` holds what ``KernelEigenspace.fit`` learned as buffers: the training
views (or the Nyström landmark views), the coefficients that map a centred kernel row to
eigenspace coordinates, and the mean kernel row used to centre it. ``forward`` evaluates
the kernel against those views and multiplies: the kernel is fixed at construction, so
the graph has no data-dependent branches and exports to ONNX.

Kernels follow ``sklearn.metrics.pairwise``: ``linear`` x·y, ``poly`` (γ x·y + c0)^d,
``rbf`` exp(−γ‖x − y‖²) and ``cosine`` x·y / (‖x‖ ‖y‖), with γ = 1/N when not given
(scikit-learn's ``KernelPCA`` default, 1/n_features).
"""

from __future__ import annotations

from typing import Any, ClassVar

import torch

from torch_eigview.check import (
    check_choice,
    check_float_tensor,
    check_image_shape,
    check_kernel_params,
    check_ndim,
)
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
from torch_eigview.nn.functional import unit_rows

__all__ = ["KERNELS", "KernelProjection", "pairwise_kernel"]

KERNELS = ("rbf", "poly", "cosine", "linear")


def pairwise_kernel(
    x: torch.Tensor,
    y: torch.Tensor,
    kernel: str,
    gamma: float,
    degree: int,
    coef0: float,
    y_sqnorm: torch.Tensor | None = None,
) -> torch.Tensor:
    """The kernel matrix k(x_i, y_j) of two sets of vectors (trusted inputs).

    Args:
        x: (P, N) vectors.
        y: (Q, N) vectors of x's dtype.
        kernel: one of ``KERNELS``.
        gamma, degree, coef0: the kernel's parameters (γ for rbf and poly).
        y_sqnorm: optional (Q,) precomputed ``‖y_j‖²`` (rbf and cosine).

    Returns:
        (P, Q) kernel values.
    """
    if kernel == "linear":
        return x @ y.T
    if kernel == "poly":
        return (gamma * (x @ y.T) + coef0) ** degree
    if y_sqnorm is None:
        y_sqnorm = y.square().sum(dim=1)
    tiny = torch.finfo(x.dtype).tiny
    if kernel == "cosine":
        # Zero rows give zero similarity, as sklearn's ``normalize`` leaves them at zero;
        # x is scaled before its norm is taken (unit_rows), so no scale overflows.
        return unit_rows(x) @ (y / y_sqnorm.sqrt().clamp_min(tiny)[:, None]).T
    # rbf: ‖x − y‖² expanded as ‖x‖² − 2 x·y + ‖y‖² (one matrix product, as sklearn's
    # ``euclidean_distances``), clamped at 0 against rounding.
    sq = x.square().sum(dim=1, keepdim=True) - 2 * (x @ y.T) + y_sqnorm
    return torch.exp(-gamma * sq.clamp_min(0))


class KernelProjection(FrozenProjection):
    """Projects views onto a frozen kernel eigenspace: ``z = (k(x, V) − k̄) @ A``.

    V are the T stored views (all training views, or the Nyström landmarks), A the (T, k)
    coefficients and k̄ the (T,) mean kernel row of the training set. For exact kernel PCA
    A holds scikit-learn's scaled eigenvectors α/√λ of the centred kernel matrix; their
    columns sum to zero, so the test-side centring term of ``KernelCenterer`` (the row
    mean of k(x, V) minus the grand mean, times 1ᵀA) is zero and left out of the graph.
    For Nyström A = W^{-1/2}U maps the landmark features to their principal axes.

    Inputs of any floating dtype are cast to the buffers' dtype, as in ``EigenProjection``.
    All tensors are persistent buffers; the kernel and its parameters are fixed at
    construction (saved in ``state_dict`` as extra state) and become constants of an
    exported graph. Only the named kernels are supported: a callable kernel could neither
    be exported nor saved in a ``state_dict``, so ``KernelEigenspace.to_module`` refuses it.

    Built from sizes (T, N, k), the buffers start as zeros for ``load_state_dict`` to fill,
    and the kernel, its parameters, ``image_shape`` and ``unit_norm`` come back from the
    saved extra state. :meth:`from_tensors` builds the layer from a fit's tensors; passing
    them here in place of the sizes is deprecated (the same, with a ``DeprecationWarning``).

    Args:
        n_vectors: T, the number of stored views; or the (T, N) stored views V, N = C*H*W
            (the tensor form).
        n_features: N; or the (T, k) coefficients A (the tensor form).
        n_components: k; or the (T,) mean kernel row k̄ of the training views against V
            (the tensor form).
        kernel: one of "rbf", "poly", "cosine", "linear".
        gamma: γ of rbf and poly, > 0; None means 1/N.
        degree: degree of poly, int >= 1.
        coef0: c0 of poly.
        eigenvalues: tensor form only: optional (k,) eigenvalues of the centred kernel
            matrix (kept for reference; an empty (0,) buffer when omitted).
        image_shape: (C, H, W) of a view, or None (saved as extra state).
        unit_norm: divide each input view by its L2 norm first (the views fitted must
            then have been unit-norm too), as in ``EigenProjection``.
        dtype: dtype of the buffers (default: the tensors', or torch's default for sizes).
        device: device of the buffers (default: the tensors', or the CPU for sizes).

    Raises:
        TypeError: a size is not an integer, a tensor argument is not a floating tensor,
            dtypes differ, the kernel is not a str, or eigenvalues are given with sizes.
        ValueError: a size below 1, inconsistent shapes, non-finite values, an unknown
            kernel or bad kernel parameters.

    Example:
        >>> vectors, coefficients = torch.eye(4), torch.ones(4, 2) / 4
        >>> m = KernelProjection.from_tensors(vectors, coefficients, torch.full((4,), 0.25), kernel="linear")
        >>> m(torch.ones(3, 4)).shape
        torch.Size([3, 2])
        >>> fresh = KernelProjection(4, 4, 2)
        >>> _ = fresh.load_state_dict(m.state_dict())
        >>> fresh.kernel
        'linear'
    """

    vectors: torch.Tensor
    coefficients: torch.Tensor
    kernel_mean: torch.Tensor
    vectors_sqnorm: torch.Tensor
    _STATE_KEYS: ClassVar[tuple[str, ...]] = (
        "kernel",
        "gamma",
        "degree",
        "coef0",
        "image_shape",
        "unit_norm",
    )

    def __init__(
        self,
        n_vectors: int | torch.Tensor,
        n_features: int | torch.Tensor,
        n_components: int | torch.Tensor,
        kernel: str = "rbf",
        gamma: float | None = None,
        degree: int = 3,
        coef0: float = 1.0,
        eigenvalues: torch.Tensor | None = None,
        image_shape: tuple[int, int, int] | None = None,
        unit_norm: bool = False,
        *,
        dtype: torch.dtype | None = None,
        device: torch.device | str | None = None,
    ) -> None:
        if callable(kernel) and not isinstance(kernel, str):
            raise TypeError(
                "kernel must be a str, one of ('rbf', 'poly', 'cosine', 'linear'), got a callable: "
                "a callable kernel cannot be exported to ONNX nor saved in a state_dict"
            )
        kernel = check_choice(kernel, "kernel", KERNELS)
        gamma, degree, coef0 = check_kernel_params(gamma, degree, coef0)
        super().__init__(unit_norm)
        self.kernel, self.degree, self.coef0 = kernel, degree, coef0
        tensors: tuple[torch.Tensor, ...]
        if is_size(n_vectors):
            sizes = [(n_vectors, "n_vectors"), (n_features, "n_features"), (n_components, "n_components")]
            t, n, k = check_sizes(sizes, eigenvalues)
            tensors = (torch.zeros(t, n), torch.zeros(t, k), torch.zeros(t))
        else:
            warn_tensor_form("KernelProjection", "vectors, coefficients, kernel_mean, ...")
            values, names = (n_vectors, n_features, n_components), ("vectors", "coefficients", "kernel_mean")
            tensors = tuple(check_float_tensor(v, name) for v, name in zip(values, names, strict=True))
        self._register(tensors, eigenvalues)
        self.gamma = 1.0 / self.in_features if gamma is None else gamma
        self.image_shape = check_image_shape(image_shape, self.in_features, "image_shape")
        self._convert(dtype, device)

    @classmethod
    def from_tensors(
        cls, vectors: torch.Tensor, coefficients: torch.Tensor, kernel_mean: torch.Tensor, **options: Any
    ) -> KernelProjection:
        """The layer holding copies of a kernel fit's tensors.

        Args:
            vectors: (T, N) stored views.
            coefficients: (T, k) map from a centred kernel row to coordinates.
            kernel_mean: (T,) mean kernel row of the training views against ``vectors``.
            **options: the class's keyword arguments (``kernel``, ``gamma``, ``degree``,
                ``coef0``, ``eigenvalues``, ``image_shape``, ``unit_norm``, ``dtype``, ``device``).

        Raises:
            TypeError, ValueError: as for the class.
        """
        vectors = check_float_tensor(vectors, "vectors")
        with from_tensors_call():
            return cls(vectors, coefficients, kernel_mean, **options)

    def _register(self, tensors: tuple[torch.Tensor, ...], eigenvalues: torch.Tensor | None) -> None:
        """Checks (vectors, coefficients, kernel_mean) against each other and registers copies."""
        vectors, coefficients, kernel_mean = tensors
        for tensor, name, layout, ndim in (
            (vectors, "vectors", "(T, N)", 2),
            (coefficients, "coefficients", "(T, k)", 2),
            (kernel_mean, "kernel_mean", "(T,)", 1),
        ):
            check_ndim(tensor, name, (ndim,), layout)
        n_vectors, n_features = vectors.shape
        if n_vectors < 1 or n_features < 1 or coefficients.shape[1] < 1:
            raise ValueError(
                f"vectors (T, N) and coefficients (T, k) must have T, N, k >= 1, "
                f"got {tuple(vectors.shape)} and {tuple(coefficients.shape)}"
            )
        if coefficients.shape[0] != n_vectors or kernel_mean.shape[0] != n_vectors:
            raise ValueError(
                f"coefficients must have shape ({n_vectors}, k) and kernel_mean ({n_vectors},) "
                f"to match vectors of shape {tuple(vectors.shape)}, got {tuple(coefficients.shape)} "
                f"and {tuple(kernel_mean.shape)}"
            )
        eigenvalues = check_eigenvalues(eigenvalues, coefficients.shape[1], vectors)
        others = [(coefficients, "coefficients"), (kernel_mean, "kernel_mean"), (eigenvalues, "eigenvalues")]
        check_same_dtype(others, vectors, "vectors")
        check_all_finite([(vectors, "vectors"), *others])
        vectors = vectors.detach().clone(memory_format=torch.contiguous_format)
        self.register_buffer("vectors", vectors)
        self.register_buffer(
            "coefficients", coefficients.detach().clone(memory_format=torch.contiguous_format)
        )
        self.register_buffer("kernel_mean", kernel_mean.detach().clone())
        # ‖v‖² of the stored views, precomputed for rbf and cosine.
        self.register_buffer("vectors_sqnorm", vectors.square().sum(dim=1))
        self._register_eigenvalues(eigenvalues, vectors.device)

    @property
    def in_features(self) -> int:
        """N, the number of values in one view."""
        return self.vectors.shape[1]

    @property
    def n_components(self) -> int:
        """k, the dimension of the eigenspace."""
        return self.coefficients.shape[1]

    @property
    def n_vectors(self) -> int:
        """T, the number of stored views (training views or Nyström landmarks)."""
        return self.vectors.shape[0]

    def _project(self, v: torch.Tensor) -> torch.Tensor:
        """(B, N) prepared views → (B, k) coordinates: kernel rows, centred, times A."""
        rows = pairwise_kernel(
            v, self.vectors, self.kernel, self.gamma, self.degree, self.coef0, self.vectors_sqnorm
        )
        return (rows - self.kernel_mean) @ self.coefficients

    def get_extra_state(self) -> dict[str, Any]:
        """Saves the kernel, its parameters, ``image_shape`` and ``unit_norm`` (not tensors)."""
        kernel_state = {
            "kernel": self.kernel,
            "gamma": self.gamma,
            "degree": self.degree,
            "coef0": self.coef0,
        }
        return {**kernel_state, **super().get_extra_state()}

    def _restore(self, state: dict[str, Any]) -> None:
        self.kernel = check_choice(state["kernel"], "kernel", KERNELS)
        gamma, self.degree, self.coef0 = check_kernel_params(state["gamma"], state["degree"], state["coef0"])
        self.gamma = 1.0 / self.in_features if gamma is None else gamma
        super()._restore(state)

    def _describe(self) -> str:
        text = f"{super()._describe()}, n_vectors={self.n_vectors}, kernel={self.kernel!r}"
        if self.kernel in ("rbf", "poly"):
            text += f", gamma={self.gamma:g}"
        if self.kernel == "poly":
            text += f", degree={self.degree}, coef0={self.coef0:g}"
        return text
