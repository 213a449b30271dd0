"""Portilla–Simoncelli statistics as a texture descriptor and distance.

The statistics are those the ``portilla_simoncelli`` method imposes
(:mod:`texsyn.models.portilla`, ``docs/methods/portilla_simoncelli.md``), measured here on
an image's RGB channels as given.
"""

from __future__ import annotations

import numpy as np

from .._validation import as_exemplar
from ..models.portilla import PSStatistics, statistics_distance
from ..models.portilla import ps_statistics as model_statistics
from ..ops.linalg import fixed_order
from ..transforms.steerable import max_scales
from .texture import check_pair

__all__ = ["ps_distance", "ps_statistics"]


@fixed_order
def ps_statistics(image, *, n_scales: int = 4, n_orientations: int = 4, lags: int = 3) -> PSStatistics:
    """Portilla-Simoncelli statistics of a grey or colour image, as a texture descriptor.

    The joint statistics of a complex steerable pyramid (Portilla and Simoncelli 2000,
    section 3; colour: every cross-channel correlation, Vacher and Briand 2021), computed on
    the RGB channels as given. ``n_scales`` is reduced for images too small for it.
    ``ps_statistics(img).vector()`` is one flat vector; ``.groups()`` splits it by family.
    """
    img = np.asarray(as_exemplar(image, name="image"), dtype=np.float64)
    scales = max_scales(img.shape[:2], n_scales)
    return model_statistics(img, n_scales=scales, n_orientations=n_orientations, lags=lags)


@fixed_order
def ps_distance(image, exemplar, *, n_scales: int = 4, n_orientations: int = 4, lags: int = 3) -> float:
    """Relative distance between the Portilla-Simoncelli statistics of two textures.

    For each family of statistics (pixel, low-pass, magnitude, cross-correlation, phase,
    high-pass) the Euclidean distance divided by the norm of the exemplar's family, then the
    mean over families (0 = same statistics, larger when they differ). Images may differ in size.
    """
    img, ex = check_pair(image, exemplar)
    scales = min(max_scales(img.shape[:2], n_scales), max_scales(ex.shape[:2], n_scales))
    a = model_statistics(
        img[..., 0] if img.shape[2] == 1 else img, n_scales=scales, n_orientations=n_orientations, lags=lags
    )
    b = model_statistics(
        ex[..., 0] if ex.shape[2] == 1 else ex, n_scales=scales, n_orientations=n_orientations, lags=lags
    )
    return float(np.mean(list(statistics_distance(a, b).values())))
