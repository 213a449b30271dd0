"""What makes the statistical methods (Heeger-Bergen, random phase noise, Portilla-Simoncelli)
what they are (issue 16): the statistics each one imposes, compared with the exemplar's, with
bounds that a shuffled-pixel output and a blurred output both exceed.

Every bound was set from measurements on the exemplar below (a 40x40 crop of gravel), output
48x48, seeds 0-5, for the real output, a shuffled-pixel version and a blurred version
(sigma 1.5) as ``tests/sabotage.py`` makes them; the measured ranges are in the comments.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import texsyn
from conftest import FAST_PARAMS
from strength_utils import GRAVEL as EXEMPLAR
from strength_utils import SEEDS, SHAPE, band_log2_ratios
from texsyn.metrics import ps_statistics, spectrum_distance
from texsyn.ops import periodic_smooth_decomposition


@functools.cache
def fitted(name: str):
    return texsyn.make_method(name, **FAST_PARAMS[name]).fit(EXEMPLAR)


@functools.cache
def sample(name: str, seed: int, shape: tuple[int, int] = SHAPE) -> np.ndarray:
    return fitted(name).sample(shape, rng=seed)


# ------------------------------------------------------------------ Heeger-Bergen
# log2 of the mean subband energy, output over exemplar, for the scales HB matches
# (n_scales=2: high-pass residual, scale 0, scale 1), real / shuffled / blurred:
#   high-pass  0.15..0.26 / 4.82..4.87 / -7.77..-6.97
#   scale 0   -0.26..-0.17 / 1.65..1.75 / -5.54..-5.09
#   scale 1   -0.08..0.12 / -1.45..-1.09 / -1.76..-1.25      -> |log2 ratio| < 0.75 each
@pytest.mark.method("heeger_bergen")
def test_heeger_bergen_reproduces_the_subband_energies_of_every_matched_scale():
    n_scales = fitted("heeger_bergen").n_scales
    for seed in SEEDS:
        ratios = band_log2_ratios(sample("heeger_bergen", seed), EXEMPLAR, n_scales)
        assert np.all(np.abs(ratios) < 0.75), (seed, ratios)


# spectrum_distance real 0.09-0.18 / shuffled 1.02-1.05 / blurred 1.68-1.83 -> < 0.45
@pytest.mark.method("heeger_bergen")
def test_heeger_bergen_reproduces_the_power_spectrum():
    for seed in SEEDS:
        assert spectrum_distance(sample("heeger_bergen", seed), EXEMPLAR) < 0.45, seed


# ------------------------------------------------------------------ random phase noise
@pytest.mark.method("random_phase")
def test_random_phase_same_size_output_has_the_periodic_components_modulus():
    periodic = periodic_smooth_decomposition(EXEMPLAR.astype(np.float64))[0]
    modulus_ex = np.abs(np.fft.fft2(periodic))
    for seed in SEEDS:
        out = sample("random_phase", seed, EXEMPLAR.shape).astype(np.float64)
        assert 0 < out.min() and out.max() < 1  # nothing clipped
        np.testing.assert_allclose(np.abs(np.fft.fft2(out)), modulus_ex, atol=1e-4 * modulus_ex.max())
        assert np.abs(out - periodic).mean() > 0.05  # the phase changed (0.13-0.16 measured)


# A larger output has the spot's (zero-padded) autocovariance, not the exact modulus; its
# subband energies stay the exemplar's at every scale (3 scales + high-pass), real / shuffled /
# blurred:  high-pass 0.27..0.31 / 4.96..5.03 / -7.60..-6.40;  scale 0 0.11..0.15 / 1.81..1.95 /
# -4.85..-4.78;  scale 1 0.02..0.07 / -1.27..-1.02 / -1.78..-1.72;  scale 2 0.23..0.30 /
# -3.68..-2.62 / -0.28..-0.22  -> |log2 ratio| < 0.7 each
@pytest.mark.method("random_phase")
def test_random_phase_larger_output_keeps_the_subband_energies():
    for seed in SEEDS:
        ratios = band_log2_ratios(sample("random_phase", seed), EXEMPLAR, 3)
        assert np.all(np.abs(ratios) < 0.7), (seed, ratios)


# spectrum_distance real 0.078-0.086 / shuffled 1.02-1.08 / blurred 1.55-1.77 -> < 0.3
@pytest.mark.method("random_phase")
def test_random_phase_larger_output_keeps_the_power_spectrum():
    for seed in SEEDS:
        assert spectrum_distance(sample("random_phase", seed), EXEMPLAR) < 0.3, seed


# ------------------------------------------------------------------ Portilla-Simoncelli
def family_distances(image, exemplar, n_scales: int) -> dict[str, float]:
    """Relative distance of each family of PS statistics (``ps_distance`` before the mean)."""
    a = ps_statistics(image, n_scales=n_scales).groups()
    b = ps_statistics(exemplar, n_scales=n_scales).groups()
    out = {}
    for key, ref in b.items():
        n = min(a[key].size, ref.size)  # auto-correlation windows cut by the smaller image
        out[key] = float(np.linalg.norm(a[key][:n] - ref[:n]) / np.linalg.norm(ref[:n]))
    return out


# PS statistics (same pyramid as the synthesis, n_scales=2), relative distance per family,
# real / shuffled / blurred:
#   magnitude (means and auto-correlations of the band magnitudes)  0.108-0.128 / 0.56-0.61 / 0.63-0.65
#   high-pass residual variance                                     0.195-0.234 / 19.2-20.1 / 1.00
#   -> magnitude < 0.3, high-pass < 0.5
@pytest.mark.method("portilla_simoncelli")
def test_portilla_simoncelli_imposes_the_magnitude_and_highpass_statistics():
    n_scales = fitted("portilla_simoncelli").n_scales
    for seed in SEEDS:
        d = family_distances(sample("portilla_simoncelli", seed), EXEMPLAR, n_scales)
        assert d["magnitude"] < 0.3, (seed, d)
        assert d["highpass"] < 0.5, (seed, d)


# log2 subband energy ratios (3 scales + high-pass), real within -0.21..0.15; shuffled
# high-pass 4.80..4.85, blurred high-pass -8.30..-7.36 -> |log2 ratio| < 0.6 each
@pytest.mark.method("portilla_simoncelli")
def test_portilla_simoncelli_keeps_the_subband_energies():
    for seed in SEEDS:
        ratios = band_log2_ratios(sample("portilla_simoncelli", seed), EXEMPLAR, 3)
        assert np.all(np.abs(ratios) < 0.6), (seed, ratios)
