"""Deprecated alias of :mod:`texsyn.models.gaussian` (the local Gaussian patch model).

The locally Gaussian model is what LG, CLG, RCLG and MSLG fit, so it lives with the other
models now (``docs/architecture.md``).
"""

import warnings

warnings.warn(
    "texsyn.ops.gaussian is deprecated; use texsyn.models.gaussian", DeprecationWarning, stacklevel=2
)

from ..models.gaussian import *  # noqa: F403, E402
from ..models.gaussian import LocalGaussian, local_gaussian  # noqa: F401,E402
