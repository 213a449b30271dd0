"""Deprecated alias of :mod:`texsyn.transforms.steerable` (the real steerable pyramid).

Kept so that ``from texsyn.ops.steerable import SteerablePyramid`` keeps working; new code
imports :mod:`texsyn.transforms.steerable` (``docs/architecture.md``).
"""

import warnings

warnings.warn(
    "texsyn.ops.steerable is deprecated; use texsyn.transforms.steerable", DeprecationWarning, stacklevel=2
)

from ..transforms.steerable import *  # noqa: F403, E402
from ..transforms.steerable import (  # noqa: F401,E402
    Pyramid,
    SteerablePyramid,
    oriented_windows,
    pyramid_sizes,
    radial_lowpass,
)
