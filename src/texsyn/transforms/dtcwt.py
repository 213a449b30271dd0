"""2-D dual-tree complex wavelet transform (Kingsbury's Q-shift DT-CWT).

Six oriented complex subbands per level (about +15, +45, +75, -75, -45, -15 degrees as
displayed), an undecimated biorthogonal finest level and decimating Q-shift coarser levels,
with half-sample symmetric extension; the layout of Kingsbury's toolbox with 0-based levels,
the finest first (``docs/architecture.md``, "Vocabulary"): ``highpasses[level]`` is
``(H / 2^(level+1), W / 2^(level+1), 6)`` complex and the low-pass is
``(H / 2^(L-1), W / 2^(L-1))`` for ``L`` levels. ``docs/methods/cwt.md`` describes its use
in Gallagher and Kokaram's synthesis.

References
----------
N. Kingsbury, "Complex wavelets for shift invariant analysis and filtering of signals",
Applied and Computational Harmonic Analysis 10 (2001). N. Kingsbury, "Design of Q-shift
complex wavelets for image processing using frequency domain energy minimisation", ICIP 2003.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..ops.patches import extend_index
from .coefficients import Coefficients
from .dtcwt_filters import FILTERS

__all__ = ["DTCWT", "DTCWTPyramid"]


@dataclass
class DTCWTPyramid(Coefficients):
    """DT-CWT coefficients (a :class:`~texsyn.transforms.coefficients.Coefficients`): ``lowpass`` and ``highpasses[level]`` of shape ``(h, w, 6)``.

    Levels are 0-based, the finest first, as in every transform of :mod:`texsyn.transforms`.

    Attributes
    ----------
    lowpass : ndarray, shape (H / 2^(L-1), W / 2^(L-1))
        Real low-pass image.
    highpasses : list of ndarray
        ``highpasses[level]`` of shape ``(H / 2^(level+1), W / 2^(level+1), 6)``, complex:
        the six oriented subbands of that level.

    Coefficients can also be addressed as ``pyr['lowpass']`` and ``pyr[level, band]``
    (``= highpasses[level][..., band]``); :meth:`keys` lists every address in a fixed order.

    Examples
    --------
    >>> pyr = DTCWT(2).forward(np.zeros((8, 8)))
    >>> pyr.levels, pyr[1, 0].shape, pyr["lowpass"].shape
    (2, (2, 2), (4, 4))
    """

    lowpass: np.ndarray
    highpasses: list[np.ndarray] = field(default_factory=list)

    @property
    def levels(self) -> int:
        """Number of levels ``L``."""
        return len(self.highpasses)

    def keys(self) -> list:
        """Every coefficient address: ``(level, band)`` pairs, the finest first, then ``'lowpass'``."""
        out: list = [(level, band) for level in range(self.levels) for band in range(6)]
        out.append("lowpass")
        return out

    def __getitem__(self, key):
        if key == "lowpass":
            return self.lowpass
        level, band = key
        return self.highpasses[level][..., band]


def _along(x: np.ndarray, axis: int, fn) -> np.ndarray:
    """``fn`` applied along ``axis``, moved first.

    ``fn`` gathers rows of the moved array (``v[index]``); the moved array is made
    contiguous first (:func:`_contiguous`), so that each gathered row is read in one
    stretch instead of one element a row apart (a column of a large image crosses a memory
    page per element). The gathered arrays are the same C-ordered arrays either way, hence
    the same sums.
    """
    return np.moveaxis(fn(_contiguous(np.moveaxis(x, axis, 0))), 0, axis)


#: side of the tiles of :func:`_contiguous`'s copy
_TILE = 64


def _contiguous(v: np.ndarray) -> np.ndarray:
    """A C-contiguous copy of ``v`` (``v`` itself when it is one already).

    A large 2-D view (the transposed images of the column filters) is copied tile by tile:
    the plain copy of a transposed image reads one element per memory page and runs two to
    three times slower on images of 1024 pixels a side and more. A copy, so the same values.
    """
    if v.flags.c_contiguous or v.ndim != 2 or v.size < 1 << 16:
        return np.ascontiguousarray(v)
    out = np.empty(v.shape, dtype=v.dtype)
    for i in range(0, v.shape[0], _TILE):
        for j in range(0, v.shape[1], _TILE):
            out[i : i + _TILE, j : j + _TILE] = v[i : i + _TILE, j : j + _TILE]
    return out


#: values of the gathered ``rows x taps x width`` block each filtering step holds (2 MiB): the
#: rows are filtered block by block, so that the gathered taps stay in the cache instead of
#: making one temporary of ``taps`` times the image (235 MiB for a 2048 x 2048 image)
_BLOCK_VALUES = 1 << 18


def _filter_rows(v: np.ndarray, index: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``einsum('rl...,l->r...', v[index], h)``: row ``r`` is ``sum_l h[l] v[index[r, l]]``.

    Computed over blocks of rows (:data:`_BLOCK_VALUES`); each output value is the same sum,
    in the same order, as with the whole gathered array, so the bytes do not change.
    """
    rows, taps = index.shape
    width = int(np.prod(v.shape[1:], dtype=np.int64))
    step = max(1, _BLOCK_VALUES // max(1, taps * width))
    if step >= rows:
        return np.einsum("rl...,l->r...", v[index], h)
    out = np.empty((rows,) + v.shape[1:], dtype=np.result_type(v, h))
    for start in range(0, rows, step):
        out[start : start + step] = np.einsum("rl...,l->r...", v[index[start : start + step]], h)
    return out


def _full(x: np.ndarray, h: np.ndarray, axis: int) -> np.ndarray:
    """Operator F: ``y(i) = sum_l h[l] x~(i + c - l)`` (odd length ``2c + 1``, no decimation)."""

    def fn(v):
        r, m = v.shape[0], h.size
        c = (m - 1) // 2
        idx = extend_index(np.arange(r)[:, None] + c - np.arange(m)[None, :], r)
        return np.tensordot(v[idx], h, axes=([1], [0])) if v.ndim == 1 else _filter_rows(v, idx, h)

    return _along(x, axis, fn)


def _down(x: np.ndarray, ha: np.ndarray, hb: np.ndarray, axis: int) -> np.ndarray:
    """Operator D: Q-shift filtering and decimation by 2 of two interleaved trees."""

    def fn(v):
        r, m = v.shape[0], ha.size
        n = np.arange(r // 4)[:, None]
        taps = np.arange(m)[None, :]
        u = _filter_rows(v, extend_index(4 * n + m - 2 * taps, r), ha)
        w = _filter_rows(v, extend_index(4 * n + m + 1 - 2 * taps, r), hb)
        out = np.empty((r // 2,) + v.shape[1:], dtype=np.result_type(v, ha))
        if np.dot(ha, hb) > 0:
            out[0::2], out[1::2] = u, w
        else:
            out[0::2], out[1::2] = w, u
        return out

    return _along(x, axis, fn)


def _up(x: np.ndarray, ga: np.ndarray, gb: np.ndarray, axis: int) -> np.ndarray:
    """Operator U: Q-shift up-sampling by 2 (inverse of :func:`_down` for matching filters)."""

    def fn(v):
        r, m = v.shape[0], ga.size
        c = m // 2
        if c % 2 != 1:
            raise ValueError(f"Q-shift filters of length {m} are not supported (need m/2 odd)")
        delta = 1 if np.dot(ga, gb) > 0 else 0
        other = 1 - delta
        n = np.arange(r // 2)[:, None]
        k = np.arange(c)[None, :]
        even = extend_index(2 * n + c - 2 * k - delta, r)
        odd = extend_index(2 * n + c - 2 * k - other, r)
        out = np.zeros((2 * r,) + v.shape[1:], dtype=np.result_type(v, ga))
        out[0::4] = _filter_rows(v, even, ga[0::2])
        out[1::4] = _filter_rows(v, odd, gb[0::2])
        out[2::4] = _filter_rows(v, even, ga[1::2])
        out[3::4] = _filter_rows(v, odd, gb[1::2])
        return out

    return _along(x, axis, fn)


def _q2c(band: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, b = band[0::2, 0::2], band[0::2, 1::2]
    c, d = band[1::2, 0::2], band[1::2, 1::2]
    p = (a + 1j * b) / np.sqrt(2)
    q = (d - 1j * c) / np.sqrt(2)
    return p - q, p + q


def _c2q(z1: np.ndarray, z2: np.ndarray) -> np.ndarray:
    p = (z1 + z2) / np.sqrt(2)
    q = (z1 - z2) / np.sqrt(2)
    out = np.empty((2 * z1.shape[0], 2 * z1.shape[1]))
    out[0::2, 0::2] = p.real
    out[0::2, 1::2] = p.imag
    out[1::2, 0::2] = q.imag
    out[1::2, 1::2] = -q.real
    return out


def _assemble(b_h: np.ndarray, b_d: np.ndarray, b_v: np.ndarray) -> np.ndarray:
    h0, h5 = _q2c(b_h)
    d1, d4 = _q2c(b_d)
    v2, v3 = _q2c(b_v)
    return np.stack([h0, d1, v2, v3, d4, h5], axis=-1)


class DTCWT:
    """Configured 2-D dual-tree complex wavelet transform.

    Parameters
    ----------
    levels : int
        Number of levels ``L >= 1``; image sides must be multiples of ``2^L``.
    biort : {'near_sym_a', 'near_sym_b'}
        Biorthogonal filters of level 0 (the finest).
    qshift : {'qshift_a', 'qshift_b'}
        Q-shift filters of levels 1 and coarser.

    Notes
    -----
    ``forward`` takes a real ``(H, W)`` array; transform colour channels one by one.
    ``inverse`` is linear and accepts any coefficients (e.g. copied blocks).

    Examples
    --------
    >>> x = np.random.default_rng(0).random((16, 16))
    >>> t = DTCWT(2)
    >>> bool(np.abs(t.inverse(t.forward(x)) - x).max() < 1e-12)
    True
    """

    def __init__(self, levels: int = 3, *, biort: str = "near_sym_a", qshift: str = "qshift_a"):
        if levels < 1:
            raise ValueError(f"levels must be at least 1, got {levels}")
        if biort not in ("near_sym_a", "near_sym_b"):
            raise ValueError(f"biort must be 'near_sym_a' or 'near_sym_b', got {biort!r}")
        if qshift not in ("qshift_a", "qshift_b"):
            raise ValueError(f"qshift must be 'qshift_a' or 'qshift_b', got {qshift!r}")
        self.levels = int(levels)
        self.biort = FILTERS[biort]
        self.qshift = FILTERS[qshift]

    def forward(self, image: np.ndarray) -> DTCWTPyramid:
        """Analyse a real ``(H, W)`` image."""
        x = np.asarray(image, dtype=np.float64)
        q = 2**self.levels
        if x.ndim != 2 or x.shape[0] % q or x.shape[1] % q:
            raise ValueError(
                f"DT-CWT with {self.levels} levels needs a 2-D image whose sides are multiples of "
                f"{q}, got shape {x.shape}"
            )
        b, f = self.biort, self.qshift
        lo = _full(x, b["h0o"], 0)
        hi = _full(x, b["h1o"], 0)
        lolo = _full(lo, b["h0o"], 1)
        highs = [_assemble(_full(hi, b["h0o"], 1), _full(hi, b["h1o"], 1), _full(lo, b["h1o"], 1))]
        for _ in range(1, self.levels):  # levels 1 .. L-1: Q-shift filters
            lo = _down(lolo, f["h0b"], f["h0a"], 0)
            hi = _down(lolo, f["h1b"], f["h1a"], 0)
            lolo = _down(lo, f["h0b"], f["h0a"], 1)
            highs.append(
                _assemble(
                    _down(hi, f["h0b"], f["h0a"], 1),
                    _down(hi, f["h1b"], f["h1a"], 1),
                    _down(lo, f["h1b"], f["h1a"], 1),
                )
            )
        return DTCWTPyramid(lowpass=lolo, highpasses=highs)

    def inverse(self, pyramid: DTCWTPyramid) -> np.ndarray:
        """Synthesise the image from (possibly modified) coefficients."""
        b, f = self.biort, self.qshift
        z = np.asarray(pyramid.lowpass, dtype=np.float64)
        for level in range(len(pyramid.highpasses) - 1, 0, -1):  # coarsest to level 1: Q-shift
            hp = pyramid.highpasses[level]
            b_h = _c2q(hp[..., 0], hp[..., 5])
            b_d = _c2q(hp[..., 1], hp[..., 4])
            b_v = _c2q(hp[..., 2], hp[..., 3])
            y1 = _up(z, f["g0b"], f["g0a"], 0) + _up(b_h, f["g1b"], f["g1a"], 0)
            y2 = _up(b_v, f["g0b"], f["g0a"], 0) + _up(b_d, f["g1b"], f["g1a"], 0)
            z = _up(y1, f["g0b"], f["g0a"], 1) + _up(y2, f["g1b"], f["g1a"], 1)
        hp = pyramid.highpasses[0]  # level 0: biorthogonal filters, no decimation
        b_h = _c2q(hp[..., 0], hp[..., 5])
        b_d = _c2q(hp[..., 1], hp[..., 4])
        b_v = _c2q(hp[..., 2], hp[..., 3])
        y1 = _full(z, b["g0o"], 0) + _full(b_h, b["g1o"], 0)
        y2 = _full(b_v, b["g0o"], 0) + _full(b_d, b["g1o"], 0)
        return _full(y1, b["g0o"], 1) + _full(y2, b["g1o"], 1)
