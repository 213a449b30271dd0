"""Building blocks of material stacks: replaying a source map, normal maps, value encodings.

A material is several images of one surface (albedo, normal, height, roughness, alpha) that
must stay in register (``docs/materials.md``):

- :func:`replay` carries any image of the exemplar's size along a source map (the
  ``(H, W, 2)`` int32 array of exemplar ``(row, col)`` per output pixel that copy-based
  methods return and ``texsyn synth --source-map x.npy`` writes);
- :func:`unit_normals` renormalises normal maps to unit length (stored encoded in [0, 1] as
  ``(n + 1) / 2``, or raw in [-1, 1]);
- :class:`LayerEncoding` is the policy that takes any image to the [0, 1] values every method
  works on and back: an affine map of a float image's own range when it leaves [0, 1] (a
  height in metres, HDR), never clipping; and optionally the sRGB decoding, to synthesise in
  linear light.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .color import linear_to_srgb, srgb_to_linear

__all__ = ["NORMAL_NAME", "LayerEncoding", "check_source_map", "is_normal_name", "replay", "unit_normals"]

#: file names taken for normal maps: the word ``normal`` (or ``nrm``) between separators
NORMAL_NAME = re.compile(r"(?:^|[^a-z0-9])(?:normal|normals|nrm)(?:[^a-z0-9]|$)")


def is_normal_name(name: str) -> bool:
    """Whether a file name (without its folder) names a normal map (:data:`NORMAL_NAME`).

    Examples
    --------
    >>> [is_normal_name(n) for n in ("brick_normal.png", "Normal_GL.tif", "nrm.exr", "abnormal.png")]
    [True, True, True, False]
    """
    stem = name.rsplit("/", 1)[-1].lower()
    return bool(NORMAL_NAME.search(stem))


def check_source_map(
    source_map: np.ndarray, exemplar_shape: tuple[int, ...], *, name: str = "source map"
) -> np.ndarray:
    """A source map as an int ``(h, w, 2)`` array whose positions lie inside ``exemplar_shape``.

    Raises
    ------
    InputError
        Another shape or type, or a position outside the exemplar (one line naming both).
    """
    src = np.asarray(source_map)
    if src.ndim != 3 or src.shape[2] != 2 or src.dtype.kind not in "iu" or 0 in src.shape:
        raise InputError(
            f"{name} must be an integer array of shape (H, W, 2) (exemplar row, col per pixel), "
            f"got {src.dtype} {src.shape}"
        )
    h, w = exemplar_shape[:2]
    if src.size and (src.min() < 0 or src[..., 0].max() >= h or src[..., 1].max() >= w):
        raise InputError(
            f"{name} names exemplar positions up to row {int(src[..., 0].max())}, column "
            f"{int(src[..., 1].max())} (least {int(src.min())}); the image is {w}x{h}"
        )
    return src


def replay(source_map: np.ndarray, image: np.ndarray) -> np.ndarray:
    """Carry ``image`` along a source map: output pixel ``p`` takes ``image[source_map[p]]``.

    Parameters
    ----------
    source_map : ndarray of int, shape (h, w, 2)
        Exemplar ``(row, col)`` of every output pixel (``SynthesisResult.source_map``).
    image : ndarray, shape (H, W) or (H, W, C)
        Any image of the exemplar's size (another channel of the same material), any dtype.

    Returns
    -------
    ndarray, shape (h, w) or (h, w, C), the dtype of ``image``.

    Raises
    ------
    InputError
        A map that is not ``(h, w, 2)`` integers, or that names positions outside ``image``.

    Examples
    --------
    >>> image = np.arange(12).reshape(3, 4)
    >>> replay(np.array([[[2, 3], [0, 0]]]), image).tolist()
    [[11, 0]]
    """
    img = np.asarray(image)
    src = check_source_map(source_map, img.shape)
    return img[src[..., 0], src[..., 1]]


def unit_normals(normals: np.ndarray, *, encoded: bool) -> np.ndarray:
    """Normal vectors rescaled to unit length, one pixel at a time.

    Parameters
    ----------
    normals : ndarray, shape (H, W, 3)
        ``encoded``: values ``(n + 1) / 2`` in [0, 1] (how image files store them); otherwise
        the vectors themselves.
    encoded : bool

    Returns
    -------
    ndarray of float64, same shape and encoding. A zero vector becomes ``(0, 0, 1)``.

    Examples
    --------
    >>> unit_normals(np.array([[[0.0, 0.0, 2.0]]]), encoded=False).tolist()
    [[[0.0, 0.0, 1.0]]]
    """
    arr = np.asarray(normals, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InputError(f"a normal map has three channels (x, y, z), got shape {arr.shape}")
    vectors = 2.0 * arr - 1.0 if encoded else arr
    length = np.linalg.norm(vectors, axis=2, keepdims=True)
    flat = length[..., 0] < 1e-12
    unit = vectors / np.where(length < 1e-12, 1.0, length)
    unit[flat] = (0.0, 0.0, 1.0)
    return (unit + 1.0) / 2.0 if encoded else unit


@dataclass(frozen=True)
class LayerEncoding:
    """How one image's values become the [0, 1] values methods work on, and back.

    ``to_unit``: the sRGB decoding first when ``linear`` (to synthesise in linear light), then
    ``(v - low) / (high - low)``; ``from_unit`` undoes both. ``low = 0, high = 1`` (the
    identity) for every image whose values lie in [0, 1]; a float image outside [0, 1] gets
    its own minimum and maximum (one pair for all its channels, so that vectors and linear
    relations between channels are kept). Nothing is ever clipped (``docs/materials.md``).

    Examples
    --------
    >>> height = np.array([[-2.0, 0.5], [3.0, 1.0]])
    >>> code = LayerEncoding.of(height)
    >>> code.low, code.high, code.to_unit(height).tolist()
    (-2.0, 3.0, [[0.0, 0.5], [1.0, 0.6]])
    >>> bool(np.allclose(code.from_unit(code.to_unit(height)), height))
    True
    """

    low: float = 0.0
    high: float = 1.0
    linear: bool = False

    @classmethod
    def of(cls, values: np.ndarray, *, linear: bool = False) -> LayerEncoding:
        """The encoding of an image: identity in [0, 1], else its own range (``linear`` only in [0, 1])."""
        arr = np.asarray(values)
        if arr.dtype.kind != "f" or arr.size == 0:
            return cls(linear=linear)
        low, high = float(arr.min()), float(arr.max())
        if low >= 0.0 and high <= 1.0:
            return cls(linear=linear)
        if linear:
            raise InputError(
                f"--linear decodes sRGB values in [0, 1]; this image holds values in [{low:.4g}, {high:.4g}]"
            )
        return cls(low, high if high > low else low + 1.0)

    @property
    def is_identity(self) -> bool:
        return self.low == 0.0 and self.high == 1.0 and not self.linear

    def to_unit(self, values: np.ndarray) -> np.ndarray:
        """Values in [0, 1] for the methods (float64)."""
        v = np.asarray(values, dtype=np.float64)
        if self.linear:
            v = srgb_to_linear(v)
        if self.low != 0.0 or self.high != 1.0:
            v = (v - self.low) / (self.high - self.low)
        return v

    def from_unit(self, values: np.ndarray) -> np.ndarray:
        """The image's own values from [0, 1] method output (float64)."""
        v = np.asarray(values, dtype=np.float64)
        if self.low != 0.0 or self.high != 1.0:
            v = self.low + v * (self.high - self.low)
        if self.linear:
            v = linear_to_srgb(v)
        return v

    def record(self) -> dict:
        """What a sidecar keeps: ``value_range`` (``[low, high]``) and ``linear``."""
        return {"value_range": [self.low, self.high], "linear": self.linear}
