"""Statistics shared by the tests of what makes each method that method (issue 16).

The bounds that use them live in the tests, each with the values measured for the real
output, a shuffled-pixel version and a blurred version (``tests/sabotage.py``).
"""

from __future__ import annotations

import numpy as np

import texsyn
from texsyn.ops import as_channels, periodic_smooth_decomposition
from texsyn.transforms.steerable import SteerablePyramid

#: the exemplar of the classic and statistical strength tests: a 40x40 crop of gravel at low
#: contrast, so that no method needs to clip (the DT-CWT reconstruction is compared exactly)
GRAVEL = (0.15 + 0.7 * texsyn.data.exemplar("gravel", size=40)).astype(np.float32)
#: their output size and seeds
SHAPE = (48, 48)
SEEDS = (0, 1, 2)


def coherent_fraction(source_map: np.ndarray) -> float:
    """Share of neighbour pairs copied together: the right neighbour's source is the source
    + (0, 1), the bottom neighbour's + (1, 0) (mean of both directions).

    About 1 for whole copied blocks, ~1/(exemplar pixels) for a shuffled map.
    """
    s = np.asarray(source_map, dtype=np.int64)
    right = np.all(s[:, 1:] - s[:, :-1] == (0, 1), axis=-1)
    down = np.all(s[1:, :] - s[:-1, :] == (1, 0), axis=-1)
    return 0.5 * float(right.mean() + down.mean())


def band_energies(image: np.ndarray, n_scales: int, n_orientations: int = 4) -> np.ndarray:
    """Mean squared coefficient of a steerable pyramid of the periodic component, per scale.

    Returns ``[high-pass residual, scale 0 (finest), ..., scale n_scales - 1]``, each averaged
    over orientations and channels (so that images of different sizes compare).
    """
    x = periodic_smooth_decomposition(as_channels(np.asarray(image, dtype=np.float64)))[0]
    pyr = SteerablePyramid(x.shape[:2], n_scales, n_orientations).forward(x)
    scales = [np.mean([np.mean(b**2) for b in level]) for level in pyr.bands]
    return np.array([np.mean(pyr.highpass**2)] + scales)


def band_log2_ratios(image: np.ndarray, exemplar: np.ndarray, n_scales: int) -> np.ndarray:
    """``log2`` of :func:`band_energies` of the image over the exemplar's (0 = same energy).

    A blurred image loses the fine scales (large negative values first); shuffled pixels are
    white noise (large positive values at the finest scales, negative at the coarse ones).
    """
    return np.log2(band_energies(image, n_scales) / band_energies(exemplar, n_scales))


#: lags (row, col) of :func:`near_autocorrelation`: the eight nearest neighbours up to two pixels
NEAR_LAGS = ((0, 1), (1, 0), (1, 1), (1, -1), (0, 2), (2, 0), (2, 2), (2, -2))


def near_autocorrelation(image: np.ndarray) -> np.ndarray:
    """Normalised autocorrelation of the (grey, periodic, mean-free) image at :data:`NEAR_LAGS`.

    Near 0 for shuffled pixels (white noise), closer to 1 than the exemplar's for a blurred image.
    """
    x = as_channels(np.asarray(image, dtype=np.float64)).mean(axis=2)
    x = periodic_smooth_decomposition(x)[0]
    x = x - x.mean()
    ac = np.fft.ifft2(np.abs(np.fft.fft2(x)) ** 2).real
    ac /= ac[0, 0]
    h, w = x.shape
    return np.array([ac[r % h, c % w] for r, c in NEAR_LAGS])


def autocorrelation_gap(image: np.ndarray, exemplar: np.ndarray) -> float:
    """Largest difference of :func:`near_autocorrelation` between an image and an exemplar."""
    return float(np.max(np.abs(near_autocorrelation(image) - near_autocorrelation(exemplar))))


def psnr_db(image: np.ndarray, reference: np.ndarray) -> float:
    """Peak signal-to-noise ratio in dB of ``image`` against ``reference`` (values in [0, 1])."""
    mse = float(np.mean((np.asarray(image, np.float64) - np.asarray(reference, np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)


def exemplar_window_shares(image: np.ndarray, exemplar: np.ndarray, *, size: int, tolerance: float) -> float:
    """Share of the image's ``size x size`` windows within ``tolerance`` (per-value mean squared
    error) of some exemplar window (exact nearest-patch search; ``tolerance=0``: exact copies)."""
    from texsyn.metrics import nearest_patch_field

    field = nearest_patch_field(image, exemplar, patch_size=size)
    return float(np.mean(field.distance <= tolerance))


def oriented_texture(size: int, angle_deg: float = 0.0, seed: int = 0) -> np.ndarray:
    """Wood-grain-like stripes: white noise kept in a narrow band of frequencies around one direction."""
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((size, size))
    kr = np.fft.fftfreq(size)[:, None]
    kc = np.fft.fftfreq(size)[None, :]
    a = np.radians(angle_deg)
    along = kr * np.cos(a) + kc * np.sin(a)  # frequency component across the stripes
    across = -kr * np.sin(a) + kc * np.cos(a)
    mask = np.exp(-((np.abs(along) - 0.12) ** 2) / (2 * 0.03**2)) * np.exp(-(across**2) / (2 * 0.01**2))
    img = np.real(np.fft.ifft2(np.fft.fft2(noise) * mask))
    img = (img - img.min()) / (img.max() - img.min())
    return img
