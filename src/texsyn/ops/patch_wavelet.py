"""Deprecated alias of the patch-valued wavelet transform's modules (Peyré 2007).

The transform's lifting scheme and coefficients are in :mod:`texsyn.transforms.patch_wavelet`;
the transform of an exemplar (windows, nearest-patch indexes, LLE embeddings) is in
:mod:`texsyn.models.patch_wavelet` (``docs/methods/patch_wavelet.md``).
"""

import warnings

warnings.warn(
    "texsyn.ops.patch_wavelet is deprecated; use texsyn.transforms.patch_wavelet "
    "(PatchWaveletCoefficients, planned_widths) and texsyn.models.patch_wavelet "
    "(PatchWaveletTransform, ExemplarWindows, lle_embedding)",
    DeprecationWarning,
    stacklevel=2,
)

from ..models.patch_wavelet import *  # noqa: E402, F403
from ..models.patch_wavelet import ExemplarWindows, PatchWaveletTransform, lle_embedding  # noqa: E402,F401
from ..transforms.patch_wavelet import *  # noqa: E402, F403
from ..transforms.patch_wavelet import (  # noqa: E402,F401
    PatchWaveletCoefficients,
    descriptor_dimension,
    planned_widths,
)
