"""Deprecated alias of the Portilla–Simoncelli modules, which were split by what they are.

- :mod:`texsyn.transforms.complex_steerable`: ``ComplexSteerablePyramid``;
- :mod:`texsyn.models.portilla`: ``PSStatistics``, ``ps_statistics``, ``pixel_statistics``,
  ``central_autocorrelation``, ``parent_features``, ``phase_doubled``;
- :mod:`texsyn.models.portilla_projections`: ``impose_autocorrelation``, ``impose_skewness``,
  ``impose_kurtosis``, ``adjust_correlation``, ``adjust_cross_correlation``...;
- :mod:`texsyn.methods.portilla_simoncelli`: ``ps_synthesis`` (now reporting through a
  :class:`texsyn.ops.progress.Reporter`; round 1's ``callback=`` still works, deprecated);
- :mod:`texsyn.transforms.steerable`: ``max_scales``.
"""

import warnings

warnings.warn(
    "texsyn.ops.portilla is deprecated; use texsyn.transforms.complex_steerable, texsyn.models.portilla "
    "and texsyn.models.portilla_projections",
    DeprecationWarning,
    stacklevel=2,
)

from ..methods.portilla_simoncelli import ps_synthesis  # noqa: F401,E402
from ..models.portilla import *  # noqa: F403, E402
from ..models.portilla import (  # noqa: F401,E402
    PSStatistics,
    central_autocorrelation,
    parent_features,
    phase_doubled,
    pixel_statistics,
    ps_statistics,
)
from ..models.portilla_projections import *  # noqa: F403, E402
from ..models.portilla_projections import (  # noqa: F401,E402
    adjust_correlation,
    adjust_cross_correlation,
    impose_autocorrelation,
    impose_kurtosis,
    impose_skewness,
)
from ..transforms.complex_steerable import ComplexSteerablePyramid  # noqa: F401,E402
from ..transforms.steerable import max_scales  # noqa: F401,E402
