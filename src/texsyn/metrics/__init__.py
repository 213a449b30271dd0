"""Texture metrics: how close a synthesis is to its exemplar and how much it copies.

A metric judges any image, whoever made it: it never imports a method. All take the
synthesised image first and the exemplar second (float arrays in [0, 1], same channels,
any sizes).
"""

from __future__ import annotations

from ..ops.linalg import fixed_order
from .patches import (
    PATCH_SIZE,
    CopyMap,
    NearestPatchField,
    completeness,
    copy_map,
    innovation,
    nearest_patch_field,
    patch_coherence,
    source_map_regions,
    synthesis_map,
)
from .statistics import ps_distance, ps_statistics
from .texture import (
    box_null_energy_share,
    contrast_ratio,
    gradient_energy_ratio,
    histogram_distance,
    laplacian_band_energies,
    local_mean_spread,
    mean_coherence,
    mean_gradient,
    radial_log_spectrum,
    rms_gradient,
    sharpness_ratio,
    source_seam_cost,
    spectrum_distance,
)

__all__ = [
    "METRIC_DESCRIPTIONS",
    "CopyMap",
    "box_null_energy_share",
    "NearestPatchField",
    "completeness",
    "contrast_ratio",
    "copy_map",
    "evaluate",
    "gradient_energy_ratio",
    "histogram_distance",
    "innovation",
    "laplacian_band_energies",
    "local_mean_spread",
    "source_seam_cost",
    "mean_coherence",
    "mean_gradient",
    "nearest_patch_field",
    "patch_coherence",
    "ps_distance",
    "ps_statistics",
    "radial_log_spectrum",
    "rms_gradient",
    "sharpness_ratio",
    "spectrum_distance",
    "source_map_regions",
    "synthesis_map",
]

#: what :func:`evaluate` reports, in order, with one line each (used by the report)
METRIC_DESCRIPTIONS = {
    "histogram_distance": "Wasserstein-2 distance of the pixel histograms (0 = same)",
    "spectrum_distance": "RMS difference of radially averaged log10 power spectra (0 = same)",
    "patch_coherence": "mean MSE from each output patch to its nearest exemplar patch (0 = all patches occur in the exemplar)",
    "completeness": "share of the exemplar covered by the patches the output uses",
    "reverse_distance": "mean MSE from each exemplar patch to its nearest output patch",
    "largest_copy": "largest verbatim-copied region, as a share of the output",
    "copied_share": "share of the output inside copied regions of at least 16x16 pixels",
    "sharpness_ratio": "mean gradient magnitude, output over exemplar (1 = as sharp)",
    "contrast_ratio": "standard deviation of the luma, output over exemplar (1 = same contrast)",
    "ps_distance": "relative distance of the Portilla-Simoncelli statistics, mean over families (0 = same)",
}


@fixed_order
def evaluate(
    image, exemplar, *, patch_size: int = PATCH_SIZE, field: NearestPatchField | None = None
) -> dict[str, float]:
    """Every metric of :data:`METRIC_DESCRIPTIONS` for one synthesis, sharing one search.

    Pass ``field`` (from :func:`nearest_patch_field`) to reuse a search already made.
    """
    if field is None:
        field = nearest_patch_field(image, exemplar, patch_size=patch_size)
    used = completeness(field=field)
    copies = copy_map(field=field)
    return {
        "histogram_distance": histogram_distance(image, exemplar),
        "spectrum_distance": spectrum_distance(image, exemplar),
        "patch_coherence": patch_coherence(field=field),
        "completeness": used["used"],
        "reverse_distance": used["reverse_distance"],
        "largest_copy": copies.largest,
        "copied_share": copies.copied_share,
        "sharpness_ratio": sharpness_ratio(image, exemplar),
        "contrast_ratio": contrast_ratio(image, exemplar),
        "ps_distance": ps_distance(image, exemplar),
    }
