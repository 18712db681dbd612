"""scikit-learn estimators around the eigenspaces and the whole method: NumPy in, NumPy out.

- :class:`EigenspacePCA`: :class:`~torch_eigview.decomposition.eigenspace.Eigenspace` as a
  transformer (``sklearn.decomposition.PCA``'s attributes);
- :class:`EigenspaceKernelPCA`: :class:`~torch_eigview.decomposition.kernel.KernelEigenspace`
  as a transformer (``sklearn.decomposition.KernelPCA``'s);
- :class:`FewViewRecognizerClassifier`: :class:`~torch_eigview.method.FewViewEigenspace`, the
  paper's method, as a classifier of flattened images.

Each stores its parameters as given (``get_params``/``set_params``, ``clone``), validates
them in ``fit``, keeps what it learned in attributes ending in ``_`` (``check_is_fitted``),
takes float32 or float64 arrays (other numbers become float64) and works in a ``Pipeline``
and ``GridSearchCV``. scikit-learn is an optional extra, never imported by the rest of the
package: ``pip install 'torch_eigview[sklearn]'``.
"""

from __future__ import annotations

# scikit-learn is an optional extra: without it, importing this package names the install.
try:
    import sklearn.base  # noqa: F401
except ImportError as err:
    raise ImportError(
        "torch_eigview.sklearn needs scikit-learn >= 1.6: pip install 'torch_eigview[sklearn]'"
    ) from err

from torch_eigview.sklearn.classifier import FewViewRecognizerClassifier
from torch_eigview.sklearn.transformers import EigenspaceKernelPCA, EigenspacePCA

__all__ = ["EigenspaceKernelPCA", "EigenspacePCA", "FewViewRecognizerClassifier"]
