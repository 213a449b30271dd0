"""Deprecated alias of :mod:`texsyn.transforms.dtcwt` (the dual-tree complex wavelet transform).

Kept so that ``from texsyn.ops.dtcwt import DTCWT`` (the README's path of round 1) keeps
working; new code imports :mod:`texsyn.transforms.dtcwt` (``docs/architecture.md``).
"""

import warnings

warnings.warn("texsyn.ops.dtcwt is deprecated; use texsyn.transforms.dtcwt", DeprecationWarning, stacklevel=2)

from ..transforms.dtcwt import *  # noqa: E402, F403
from ..transforms.dtcwt import DTCWT, DTCWTPyramid  # noqa: E402,F401
