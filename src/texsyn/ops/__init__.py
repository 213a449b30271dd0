"""Stateless building blocks shared by every method (spec 00). Each exists once here."""

from .color import ColorPCA, luma, rgb_to_yuv, yuv_to_rgb
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
from .pyramids import crop_to_multiple, gaussian_blur, gaussian_pyramid, zoom_in, zoom_out
from .search import (
    FFTPatchSearch,
    NearestPatchIndex,
    WeightedPatchBank,
    knn_patches,
    knn_select,
    nearest_both_ways,
)
from .seams import boundary_cut_mask, cumulative_path_cost, min_path, overlap_error
from .steerable import Pyramid, SteerablePyramid

__all__ = [
    "ColorPCA",
    "FFTPatchSearch",
    "NearestPatchIndex",
    "HistogramMatcher",
    "Pyramid",
    "SteerablePyramid",
    "WeightedPatchBank",
    "as_channels",
    "average_patches",
    "boundary_cut_mask",
    "crop_to_multiple",
    "cumulative_path_cost",
    "extend_index",
    "extract_patches",
    "gaussian_blur",
    "gaussian_pyramid",
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
    "zoom_in",
    "zoom_out",
]
