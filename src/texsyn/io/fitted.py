"""Deprecated alias of :func:`texsyn.save` and :func:`texsyn.load` (texsyn 0.1's names).

``save_fitted(path, method)`` is ``texsyn.save(method, path, overwrite=True)`` (texsyn 0.1
replaced existing files); ``load_fitted(path, **params)`` is ``texsyn.load(path, **params)``.
See ``docs/persistence.md``.
"""

import warnings

warnings.warn(
    "texsyn.io.fitted is deprecated; use texsyn.save and texsyn.load", DeprecationWarning, stacklevel=2
)

from ..persistence import load as load_fitted  # noqa: E402
from ..persistence import save  # noqa: E402

__all__ = ["load_fitted", "save_fitted"]


def save_fitted(path, method):
    """Deprecated: ``texsyn.save(method, path, overwrite=True)``."""
    return save(method, path, overwrite=True)
