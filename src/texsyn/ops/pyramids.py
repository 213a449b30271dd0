"""Deprecated alias of :mod:`texsyn.transforms.pyramids` (Gaussian pyramids, zooms, tight frame).

Kept so that ``from texsyn.ops.pyramids import LaplacianTightFrame`` keeps working; new code
imports :mod:`texsyn.transforms.pyramids` (``docs/architecture.md``).
"""

import warnings

warnings.warn(
    "texsyn.ops.pyramids is deprecated; use texsyn.transforms.pyramids", DeprecationWarning, stacklevel=2
)

from ..transforms.pyramids import *  # noqa: F403, E402
from ..transforms.pyramids import (  # noqa: F401,E402
    LaplacianTightFrame,
    crop_to_multiple,
    gaussian_blur,
    gaussian_pyramid,
    zoom_in,
    zoom_out,
)
