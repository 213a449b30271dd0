"""Colour policy: the one place where methods decide how colour images are represented.

Every method that offers a choice exposes it as one ``colour`` parameter; the method builds a
:class:`ColourSpace` with :func:`colour_space` in ``fit`` and works on its coordinates. The
allowed values (:data:`COLOUR_SPACES`):

- ``'pca'``: the exemplar's principal colour axes, decorrelated channels (Heeger and Bergen's
  colour variant as described by Briand et al., IPOL 2014; Tartavel et al. 2013,
  section 3). Portilla–Simoncelli calls it ``'joint'`` because it then measures every
  cross-channel correlation in these axes (:data:`COLOUR_ALIASES`);
- ``'grey'``: BT.601 luma only, the output is grey;
- ``'yuv'``: analogue BT.601 YUV (Gaussian-texture and wavelet methods that treat luma and
  chroma differently);
- ``'rgb'``: the channels as given.

A grey exemplar stays grey in every space. The building blocks (:func:`rgb_to_yuv`,
:func:`luma`, :class:`ColorPCA`) are here too, and the sRGB transfer function
(:func:`srgb_to_linear`, :func:`linear_to_srgb`) behind ``texsyn synth --linear``
(``docs/materials.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "COLOUR_ALIASES",
    "COLOUR_SPACES",
    "ColorPCA",
    "ColourSpace",
    "colour_space",
    "linear_to_srgb",
    "luma",
    "rgb_to_yuv",
    "srgb_to_linear",
    "yuv_to_rgb",
]

RGB_TO_YUV = np.array(
    [
        [0.299, 0.587, 0.114],
        [-0.14713, -0.28886, 0.436],
        [0.615, -0.51499, -0.10001],
    ]
)
YUV_TO_RGB = np.linalg.inv(RGB_TO_YUV)


def rgb_to_yuv(image: np.ndarray) -> np.ndarray:
    """Analogue BT.601 YUV of an ``(H, W, 3)`` RGB image (ITU-R BT.601 luma weights)."""
    return np.asarray(image, dtype=np.float64) @ RGB_TO_YUV.T


def luma(image: np.ndarray) -> np.ndarray:
    """BT.601 luma ``Y`` of an ``(..., 3)`` RGB image; a grey ``(H, W)`` image is returned as is."""
    img = np.asarray(image, dtype=np.float64)
    return img @ RGB_TO_YUV[0] if img.ndim == 3 and img.shape[-1] == 3 else img


def yuv_to_rgb(image: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rgb_to_yuv` with the exact matrix inverse."""
    return np.asarray(image, dtype=np.float64) @ YUV_TO_RGB.T


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """Linear light of sRGB-encoded values in [0, 1] (IEC 61966-2-1, the sRGB decoding).

    Examples
    --------
    >>> [round(float(v), 4) for v in srgb_to_linear(np.array([0.0, 0.5, 1.0]))]
    [0.0, 0.214, 1.0]
    """
    v = np.asarray(values, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(values: np.ndarray) -> np.ndarray:
    """sRGB encoding of linear values in [0, 1] (IEC 61966-2-1), the inverse of :func:`srgb_to_linear`.

    Examples
    --------
    >>> v = np.linspace(0.0, 1.0, 11)
    >>> bool(np.allclose(linear_to_srgb(srgb_to_linear(v)), v))
    True
    """
    v = np.clip(np.asarray(values, dtype=np.float64), 0.0, None)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1.0 / 2.4) - 0.055)


class ColorPCA:
    """Principal colour axes of a set of pixels: ``a = (u - mean) V``, ``u = a V^T + mean``.

    Used to match colour histograms along decorrelated axes (Heeger and Bergen colour
    variant, Briand et al., IPOL 2014; Tartavel et al. 2013, section 3). The sign of
    each axis is fixed (its largest component is positive).

    Parameters
    ----------
    pixels : ndarray, shape (..., C)
        Reference pixels (typically the exemplar).
    """

    def __init__(self, pixels: np.ndarray):
        flat = np.asarray(pixels, dtype=np.float64).reshape(-1, pixels.shape[-1])
        self.mean = flat.mean(axis=0)
        cov = np.cov(flat, rowvar=False).reshape(flat.shape[1], flat.shape[1])
        eigval, eigvec = np.linalg.eigh(cov)
        order = np.argsort(eigval)[::-1]
        vecs = eigvec[:, order]
        # fix the sign of each axis so that results do not depend on the LAPACK build
        signs = np.sign(vecs[np.argmax(np.abs(vecs), axis=0), np.arange(vecs.shape[1])])
        self.axes = vecs * np.where(signs == 0, 1.0, signs)
        self.variances = eigval[order]

    @classmethod
    def from_arrays(cls, mean: np.ndarray, axes: np.ndarray, variances: np.ndarray) -> ColorPCA:
        """The axes as saved (``mean``, ``axes``, ``variances``), without recomputing them.

        Examples
        --------
        >>> pca = ColorPCA(np.random.default_rng(0).random((10, 3)))
        >>> copy = ColorPCA.from_arrays(pca.mean, pca.axes, pca.variances)
        >>> bool(np.array_equal(copy.axes, pca.axes))
        True
        """
        out = cls.__new__(cls)
        out.mean = np.asarray(mean, dtype=np.float64)
        out.axes = np.asarray(axes, dtype=np.float64)
        out.variances = np.asarray(variances, dtype=np.float64)
        return out

    def forward(self, image: np.ndarray) -> np.ndarray:
        """Coordinates along the principal axes, same shape as ``image``."""
        return (np.asarray(image, dtype=np.float64) - self.mean) @ self.axes

    def inverse(self, coords: np.ndarray) -> np.ndarray:
        """Back to the original colour space."""
        return np.asarray(coords, dtype=np.float64) @ self.axes.T + self.mean


#: the allowed values of a method's ``colour`` parameter, each with what it means
COLOUR_SPACES: dict[str, str] = {
    "pca": "the exemplar's principal colour axes (decorrelated channels); grey stays grey",
    "grey": "BT.601 luma only; the output is grey",
    "yuv": "analogue BT.601 YUV; grey stays grey",
    "rgb": "the channels as given",
}

#: other names methods use for the same spaces (kept for their users)
COLOUR_ALIASES: dict[str, str] = {"joint": "pca"}


@dataclass(frozen=True)
class ColourSpace:
    """The colour representation a method works in: ``forward`` to coordinates, ``inverse`` back.

    Built by :func:`colour_space` from the exemplar in ``fit``; never changed afterwards.

    Attributes
    ----------
    name : str
        One of :data:`COLOUR_SPACES`.
    channels : int
        Number of coordinate channels (1 for a grey exemplar or the ``'grey'`` space).
    pca : ColorPCA or None
        The principal axes of the ``'pca'`` space of a colour exemplar.

    Examples
    --------
    >>> exemplar = np.random.default_rng(0).random((8, 8, 3))
    >>> space = colour_space("pca", exemplar)
    >>> space.channels, space.forward(exemplar).shape
    (3, (8, 8, 3))
    >>> bool(np.allclose(space.inverse(space.forward(exemplar)), exemplar))
    True
    >>> colour_space("grey", exemplar).inverse(np.zeros((8, 8, 1))).shape
    (8, 8)
    """

    name: str
    channels: int
    pca: ColorPCA | None = None

    def forward(self, image: np.ndarray) -> np.ndarray:
        """Coordinates ``(H, W, channels)`` of an image ``(H, W)`` or ``(H, W, C)``.

        A grey image given to a three-channel space is repeated on the three channels; a
        colour image given to a one-channel space is reduced to its luma.
        """
        img = np.asarray(image, dtype=np.float64)
        if img.ndim == 2:
            img = img[..., None]
        if self.channels == 1:
            return luma(img)[..., None] if img.shape[2] == 3 else img
        if img.shape[2] == 1:
            img = np.repeat(img, self.channels, axis=2)
        if self.pca is not None:
            return self.pca.forward(img)
        if self.name == "yuv":
            return rgb_to_yuv(img)
        return img

    def inverse(self, coords: np.ndarray) -> np.ndarray:
        """The image of coordinates ``(H, W, channels)``: ``(H, W, 3)``, or ``(H, W)`` for one channel."""
        c = np.asarray(coords, dtype=np.float64)
        if self.channels == 1:
            return c[..., 0]
        if self.pca is not None:
            return self.pca.inverse(c)
        if self.name == "yuv":
            return yuv_to_rgb(c)
        return c


def colour_space(name: str, exemplar: np.ndarray) -> ColourSpace:
    """The :class:`ColourSpace` ``name`` (or an alias in :data:`COLOUR_ALIASES`) of an exemplar.

    Parameters
    ----------
    name : str
        ``'pca'`` (alias ``'joint'``), ``'grey'``, ``'yuv'`` or ``'rgb'`` (:data:`COLOUR_SPACES`).
    exemplar : ndarray, shape (H, W) or (H, W, C)
        The pixels the principal axes are computed from; its channel count decides whether
        the space has one channel or several.

    Examples
    --------
    >>> colour_space("joint", np.zeros((4, 4))).channels  # a grey exemplar stays grey
    1
    """
    key = COLOUR_ALIASES.get(name, name)
    if key not in COLOUR_SPACES:
        allowed = sorted(COLOUR_SPACES) + sorted(COLOUR_ALIASES)
        raise ValueError(f"colour must be one of {allowed}, got {name!r}")
    ex = np.asarray(exemplar, dtype=np.float64)
    channels = 1 if ex.ndim == 2 else int(ex.shape[2])
    if key == "grey" or channels == 1:
        return ColourSpace(key, 1)
    if key == "pca":
        return ColourSpace(key, channels, ColorPCA(ex))
    return ColourSpace(key, channels)
