"""The package's exception types.

Bad values and shapes raise the built-in ``ValueError`` and wrong types ``TypeError``
(see :mod:`torch_eigview.check`); this module holds the errors of the package's own.
"""

from __future__ import annotations

__all__ = ["NotFittedError"]


class NotFittedError(ValueError, AttributeError):
    """Raised when a fitted attribute is used before ``fit`` (as in scikit-learn)."""
