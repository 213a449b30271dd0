"""Deprecated alias of :mod:`texsyn.transforms.dtcwt_filters` (Kingsbury's DT-CWT filters).

Kept so that ``from texsyn.ops.dtcwt_filters import FILTERS`` keeps working; new code imports
:mod:`texsyn.transforms.dtcwt_filters` (``docs/architecture.md``).
"""

import warnings

warnings.warn(
    "texsyn.ops.dtcwt_filters is deprecated; use texsyn.transforms.dtcwt_filters",
    DeprecationWarning,
    stacklevel=2,
)

from ..transforms.dtcwt_filters import *  # noqa: E402, F403
from ..transforms.dtcwt_filters import FILTERS  # noqa: E402, F401
