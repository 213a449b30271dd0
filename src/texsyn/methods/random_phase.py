"""Random phase noise (Galerne, Gousseau, Morel 2011).

The exemplar's Fourier modulus is kept and its phase replaced by the phase of white noise:
``fit`` takes the periodic component of the exemplar and removes its mean (the "spot"),
``sample`` draws the random phase (:func:`random_phase_noise`). ``docs/methods/random_phase.md``
maps the paper's steps to these functions.
"""

from __future__ import annotations

import numpy as np

from ..ops import as_channels, periodic_smooth_decomposition
from ..ops.canvas import crop_to_output, padded_canvas
from ._base import TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, output_bytes, pixel_count, shape_dims

__all__ = ["RandomPhase", "random_phase_noise"]


def random_phase_noise(spot: np.ndarray, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """Randomise the Fourier phase of a zero-mean ``spot``, the same phase on every channel.

    Parameters
    ----------
    spot : ndarray, shape (h, w, C)
        Zero-mean image (the exemplar's periodic component minus its mean).
    shape : (int, int)
        Output size ``(H, W)`` with ``H >= h`` and ``W >= w``. A larger output embeds the
        spot at the centre of a zero image scaled by ``sqrt(HW / hw)``, so that the output
        has the exemplar's variance and its covariance is the empirical auto-covariance
        (Galerne et al. 2011, section 4.2).

    Returns
    -------
    ndarray, shape (H, W, C), zero mean, unclipped float64. For ``(H, W) == (h, w)`` its
    Fourier modulus equals the spot's exactly.
    """
    h, w = spot.shape[:2]
    big_h, big_w = shape
    if (big_h, big_w) != (h, w):
        embedded = np.zeros((big_h, big_w, spot.shape[2]))
        top, left = (big_h - h) // 2, (big_w - w) // 2
        embedded[top : top + h, left : left + w] = spot * np.sqrt(big_h * big_w / (h * w))
        spot = embedded
    spectrum = np.fft.rfft2(spot, axes=(0, 1))
    # the phase of the DFT of white noise is uniform and Hermitian-symmetric
    noise = np.fft.rfft2(rng.standard_normal((big_h, big_w)))
    modulus = np.abs(noise)
    phase = np.divide(noise, modulus, out=np.ones_like(noise), where=modulus > 0)
    phase[0, 0] = 1.0
    return np.fft.irfft2(spectrum * phase[..., None], s=(big_h, big_w), axes=(0, 1))


class RandomPhase(TextureSynthesizer):
    """Random phase noise: keep the exemplar's Fourier modulus, draw a uniform random phase.

    Suited to micro-textures (sand, granite, clouds); structured textures lose their
    geometry. The same random phase is added to every colour channel, which keeps the
    colours' cross-spectra. Any output size.

    Parameters
    ----------
    periodic_component : bool
        Use the periodic component of the exemplar (removes the cross artefact that the
        image borders put in the spectrum).

    References
    ----------
    B. Galerne, Y. Gousseau, J.-M. Morel, "Random phase textures: theory and synthesis",
    IEEE Trans. Image Processing 20 (2011), sections 3-4.

    Examples
    --------
    >>> import texsyn
    >>> method = RandomPhase().fit(texsyn.data.exemplar("gravel", size=32))
    >>> method.sample((48, 40), rng=0).shape
    (48, 40)
    """

    name = "random_phase"
    #: channels are synthesised jointly: a material stack or an RGBA exemplar (docs/materials.md)
    max_channels = 16
    memory_margin = CALIBRATED_MARGIN
    summary = "Random phase noise: exemplar Fourier modulus with a random phase"
    reference = "Galerne, Gousseau, Morel, IEEE TIP 2011"

    def __init__(self, *, periodic_component: bool = True):
        self.periodic_component = periodic_component

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """The spot; the embedded spot, its spectrum and the random phase (``docs/memory.md``)."""
        h, w, c = shape_dims(exemplar_shape)
        k = float(h * w)
        terms = {"exemplar and spot": 16.0 * k * c}
        if output_shape is None:
            terms["periodic component"] = 24.0 * k * c + 16.0 * k
            return terms
        rows, cols = padded_canvas(output_shape, minimum=(h, w))
        canvas = float(rows) * float(cols)
        # at the inverse transform: the embedded spot, its spectrum, their product with the
        # phase, the inverse's complex intermediate and the result (8 C bytes each: the
        # spectra are half-size complex); the noise's spectrum, its modulus and the phase
        # (8 + 4 + 8) are still referenced (128 -> 512 colour: 35.8 MiB traced, 35.0 counted;
        # docs/memory.md, "Every method at its defaults"). The spectra are freed before the
        # output is cropped, shifted and converted
        terms["embedded spot, spectra and phase"] = max(
            canvas * (40.0 * c + 20.0), 8.0 * c * pixel_count(output_shape) + output_bytes(c, output_shape)
        )
        return terms

    def _fit(self, exemplar: np.ndarray) -> None:
        ex = as_channels(exemplar)
        base = periodic_smooth_decomposition(ex)[0] if self.periodic_component else ex
        self.mean_ = base.mean(axis=(0, 1))
        self.spot_ = base - self.mean_

    def periodic_for(self, shape):
        """The noise is periodic on its canvas: the output, when it is at least the exemplar."""
        return padded_canvas(shape, minimum=self.spot_.shape[:2]) == tuple(shape)

    def _sample(self, shape, rng, callback):
        canvas = padded_canvas(shape, minimum=self.spot_.shape[:2])  # at least the spot (section 4.2)
        out = crop_to_output(random_phase_noise(self.spot_, canvas, rng), shape)
        return out + self.mean_, None
