"""Deprecated alias of :mod:`texsyn.transforms.grouplets` (the grouplet transforms moved there).

``from texsyn.ops.grouplets import GroupletTransform, WaveletGroupletTransform`` keeps
working with a :class:`DeprecationWarning`; import them from :mod:`texsyn.transforms.grouplets`.
"""

import warnings

warnings.warn(
    "texsyn.ops.grouplets is deprecated; use texsyn.transforms.grouplets", DeprecationWarning, stacklevel=2
)

from ..transforms.grouplets import *  # noqa: E402,F403
from ..transforms.grouplets import GroupletTransform, WaveletGroupletTransform  # noqa: E402

__all__ = ["GroupletTransform", "WaveletGroupletTransform"]
