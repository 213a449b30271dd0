"""Layer 3, ops: stateless numerical building blocks and shared policies, each written once.

See ``docs/architecture.md``. The pyramids and the steerable pyramid moved to
:mod:`texsyn.transforms`; their old names here (``SteerablePyramid``, ``Pyramid``,
``crop_to_multiple``, ``gaussian_blur``, ``gaussian_pyramid``, ``zoom_in``, ``zoom_out``) still
resolve, with a :class:`DeprecationWarning`, through the module ``__getattr__`` below.
"""

import importlib
import warnings
from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:  # the names for type checkers; at run time ``__getattr__`` loads them
    from .color import ColorPCA, ColourSpace, colour_space, luma, rgb_to_yuv, yuv_to_rgb
    from .fourier import periodic_smooth_decomposition
    from .histogram import (
        HistogramMatcher,
        hist_target,
        match_histogram,
        match_histogram_pca,
        match_sorted,
        match_sorted_rows,
        transport_energy,
    )
    from .patches import (
        as_channels,
        average_patches,
        extend_index,
        extract_patches,
        overlap_add,
        wrap_seam_ratio,
    )
    from .positions import position_colors
    from .seams import boundary_cut_mask, cumulative_path_cost, min_path, overlap_error
    from .search import (
        FFTPatchSearch,
        NearestPatchIndex,
        WeightedPatchBank,
        knn_patches,
        knn_select,
        nearest_both_ways,
    )

#: each public name and the submodule defining it (loaded on first use: ``_lazy``)
_EXPORTS = {
    "ColorPCA": "color",
    "ColourSpace": "color",
    "colour_space": "color",
    "luma": "color",
    "rgb_to_yuv": "color",
    "yuv_to_rgb": "color",
    "periodic_smooth_decomposition": "fourier",
    "HistogramMatcher": "histogram",
    "hist_target": "histogram",
    "match_histogram": "histogram",
    "match_histogram_pca": "histogram",
    "match_sorted": "histogram",
    "match_sorted_rows": "histogram",
    "transport_energy": "histogram",
    "as_channels": "patches",
    "average_patches": "patches",
    "extend_index": "patches",
    "extract_patches": "patches",
    "overlap_add": "patches",
    "wrap_seam_ratio": "patches",
    "position_colors": "positions",
    "boundary_cut_mask": "seams",
    "cumulative_path_cost": "seams",
    "min_path": "seams",
    "overlap_error": "seams",
    "FFTPatchSearch": "search",
    "NearestPatchIndex": "search",
    "WeightedPatchBank": "search",
    "knn_patches": "search",
    "knn_select": "search",
    "nearest_both_ways": "search",
}

__all__ = [
    "ColorPCA",
    "ColourSpace",
    "FFTPatchSearch",
    "NearestPatchIndex",
    "HistogramMatcher",
    "WeightedPatchBank",
    "as_channels",
    "average_patches",
    "boundary_cut_mask",
    "colour_space",
    "cumulative_path_cost",
    "extend_index",
    "extract_patches",
    "hist_target",
    "knn_patches",
    "knn_select",
    "luma",
    "match_histogram",
    "match_histogram_pca",
    "match_sorted",
    "match_sorted_rows",
    "min_path",
    "nearest_both_ways",
    "overlap_add",
    "overlap_error",
    "periodic_smooth_decomposition",
    "position_colors",
    "rgb_to_yuv",
    "transport_energy",
    "wrap_seam_ratio",
    "yuv_to_rgb",
]

#: names this package re-exported before they moved to ``texsyn.transforms`` (deprecated here)
_MOVED = {
    "Pyramid": "texsyn.transforms.steerable",
    "SteerablePyramid": "texsyn.transforms.steerable",
    "crop_to_multiple": "texsyn.transforms.pyramids",
    "gaussian_blur": "texsyn.transforms.pyramids",
    "gaussian_pyramid": "texsyn.transforms.pyramids",
    "zoom_in": "texsyn.transforms.pyramids",
    "zoom_out": "texsyn.transforms.pyramids",
}


#: modules of this package that moved (each now a deprecated alias that warns when imported)
_MOVED_MODULES = (
    "dtcwt",
    "dtcwt_filters",
    "gaussian",
    "grouplets",
    "patch_wavelet",
    "portilla",
    "pyramids",
    "steerable",
)


def _deprecated(name: str):
    """Deprecated names: resolve those that moved to :mod:`texsyn.transforms`, with a warning.

    Called by the package's ``__getattr__`` (:func:`texsyn._lazy.lazy_exports`), so the
    user's line is three frames up.
    """
    if name in _MOVED_MODULES:  # ``texsyn.ops.dtcwt`` without importing it, as round 1 allowed
        with warnings.catch_warnings(record=True) as caught:  # re-issued at the caller's line
            warnings.simplefilter("always", DeprecationWarning)
            alias = importlib.import_module(f".{name}", __name__)
        said = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]
        warnings.warn(
            said[0] if said else f"texsyn.ops.{name} is deprecated", DeprecationWarning, stacklevel=3
        )
        return alias
    module = _MOVED.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"texsyn.ops.{name} is deprecated; use {module}.{name}", DeprecationWarning, stacklevel=3)
    return getattr(importlib.import_module(module), name)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, fallback=_deprecated)
