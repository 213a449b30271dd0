"""Coefficients of the patch-valued wavelet transform, and the thresholding of section 5.2.

G. Peyré, *Texture synthesis and modification with a patch-valued wavelet transform*, SSVM
2007, sections 4 and 5.2 (``docs/methods/patch_wavelet.md``): the coarse coordinate map and
the details of every level and axis produced by
:class:`texsyn.transforms.patch_wavelet.PatchLifting`, their magnitudes (Fig. 7), the
paper's coefficient thresholding and the local (region) thresholding that ``modify`` uses
by default.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .coefficients import Coefficients

__all__ = ["PatchWaveletCoefficients"]


@dataclass
class PatchWaveletCoefficients(Coefficients):
    """Coefficients of the patch-valued wavelet transform (section 4, Fig. 7).

    As a :class:`~texsyn.transforms.coefficients.Coefficients`, ``coefficients[j, axis]``
    addresses the details (``None`` for a missing entry) and ``coefficients['lowpass']`` the
    coarse map. The one exception to 0-based levels: ``j`` is the paper's exponent of the
    sample spacing ``2^(j-1)``, ``1 ... top_level`` (``docs/architecture.md``).

    Attributes
    ----------
    coarse : ndarray of int64, shape (c_h, c_w, 2)
        Coarse coordinate map at level ``top_level``: ``1 x 1`` after a full forward
        transform of a square map, ``2^a x 2^b`` with ``min(a, b) = 0`` after that of a
        rectangular one; ``2 x 2`` for a square synthesis.
    top_level : int
        Coarsest level ``j_top``; the full map has shape ``(c_h 2^j_top, c_w 2^j_top)``.
    details : dict
        ``details[(j, axis)]``, ``j = 1 ... top_level`` (1 is the finest), ``axis`` 0 (vertical
        pairs) or 1 (horizontal pairs): arrays ``(rows, cols, p)`` of detail vectors; a missing
        entry means zero details. Shapes, for a map of shape ``(n_h, n_w)``:
        ``(n_h/2^j, n_w/2^(j-1), p)`` for axis 0 and ``(n_h/2^j, n_w/2^j, p)`` for axis 1.
    grid_boundary : {'periodic', 'symmetric'}
        Boundary rule of the sample grid that produced them (the inverse must use the same).
    features : dict
        ``features[(j, axis)]``: int64 arrays ``(rows, cols, 2)``, the exemplar positions of
        the odd samples the details were measured from, set by :meth:`PatchLifting.forward`
        (empty for coefficients that analysed nothing, such as a synthesis's); ``-1`` marks a
        sample whose feature is not to be restored. Read by the inverse only when asked to
        restore (:meth:`PatchLifting.inverse_step`, modification by local thresholding).
    """

    coarse: np.ndarray
    top_level: int
    details: dict = field(default_factory=dict)
    grid_boundary: str = "periodic"
    features: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        """``(n_h, n_w)``: shape of the coordinate map these coefficients describe."""
        scale = 2**self.top_level
        return (self.coarse.shape[0] * scale, self.coarse.shape[1] * scale)

    @property
    def size(self) -> int:
        """Longest side of the coordinate map (its side ``n`` when it is square)."""
        return max(self.shape)

    def detail_shape(self, level: int, axis: int) -> tuple[int, int]:
        """``(rows, cols)`` of the details of ``(level, axis)``."""
        rows = self.shape[0] // 2**level
        cols = self.shape[1] // 2**level
        return (rows, 2 * cols) if axis == 0 else (rows, cols)

    @property
    def levels(self) -> int:
        """Number of detail levels (``top_level``)."""
        return int(self.top_level)

    def keys(self) -> list:
        """``(j, axis)`` for every level ``j = 1 ... top_level`` and axis, then ``'lowpass'``."""
        return [(j, axis) for j in range(1, self.levels + 1) for axis in (0, 1)] + ["lowpass"]

    def __getitem__(self, key):
        """The coarse map, or the details of ``(j, axis)`` (``None``: zero details)."""
        if key == "lowpass":
            return self.coarse
        return self.details.get(key)

    def norms(self) -> dict:
        """``||d||_2`` of every detail vector, per ``(level, axis)``."""
        return {key: np.linalg.norm(d, axis=-1) for key, d in self.details.items()}

    def detail_positions(self, level: int, axis: int) -> tuple[np.ndarray, np.ndarray]:
        """Rows and columns, in the full map, of the odd samples of ``(level, axis)``.

        At level ``j`` the samples are ``s = 2^(j-1)`` apart: the vertical pair ``(r, c)``
        predicts the sample at ``((2r + 1) s, c s)``, the horizontal one that at
        ``(2r s, (2c + 1) s)`` (Table 1: rows first, then columns).
        """
        s = 2 ** (level - 1)
        rows, cols = self.detail_shape(level, axis)
        if axis == 0:
            return (2 * np.arange(rows) + 1) * s, np.arange(cols) * s
        return 2 * np.arange(rows) * s, (2 * np.arange(cols) + 1) * s

    def detail_energy(self, *, per_level: bool = False) -> np.ndarray:
        """Local energy of the details: ``sum ||d||^2`` over the cells they cover, ``(n_h, n_w)``.

        A detail of level ``j`` speaks for the ``2s x s`` (vertical pair) or ``2s x 2s``
        (horizontal pair) cell of the map around its odd sample, ``s = 2^(j-1)``; every
        level and direction adds the squared magnitude of its details over their cells. With
        ``per_level=True`` each level's magnitudes are first divided by the level's largest.
        """
        out = np.zeros(self.shape)
        norms = self.norms()
        for level in range(1, self.top_level + 1):
            top = max((float(norms[(level, a)].max()) for a in (0, 1) if (level, a) in norms), default=0.0)
            for axis in (0, 1):
                if (level, axis) not in norms or top == 0:
                    continue
                s = 2 ** (level - 1)
                n = norms[(level, axis)] / top if per_level else norms[(level, axis)]
                cell = np.ones((2 * s, s) if axis == 0 else (2 * s, 2 * s))
                out += np.kron(n**2, cell)
        return out

    def kept_region(
        self,
        ratio: float,
        *,
        per_level: bool = False,
        smoothing: float = 4.0,
        valid: tuple[int, int] | None = None,
    ) -> np.ndarray:
        """Where local thresholding keeps the input: a boolean ``(n_h, n_w)`` map.

        The :meth:`detail_energy` map is smoothed by a Gaussian of ``smoothing`` samples and
        the share ``ratio`` of the samples with the lowest smoothed energy is removed (ties
        broken by position, C order): ``ratio = 0`` keeps everything, ``ratio = 1`` nothing,
        and the kept regions of larger ratios lie inside those of smaller ones. ``valid``
        ``(h, w)`` is the input's part of the grid (its top-left corner; the rest extends it
        to powers of two): the share is counted there, and an extension sample is removed
        when its energy is at most that of the last valid sample removed.
        """
        if not 0.0 <= ratio <= 1.0:
            raise ValueError(f"ratio must be in [0, 1], got {ratio!r}")
        energy = self.detail_energy(per_level=per_level)
        if smoothing > 0:  # scipy.ndimage imported here: synthesis never needs it (start-up)
            from scipy.ndimage import gaussian_filter

            energy = gaussian_filter(energy, float(smoothing), mode="reflect")
        h, w = energy.shape if valid is None else (int(valid[0]), int(valid[1]))
        inside = energy[:h, :w]
        order = np.argsort(inside, axis=None, kind="stable")
        removed = int(round(ratio * inside.size))
        keep_inside = np.ones(inside.size, dtype=bool)
        keep_inside[order[:removed]] = False
        if removed == 0:
            keep = np.ones(energy.shape, dtype=bool)
        elif removed == inside.size:
            keep = np.zeros(energy.shape, dtype=bool)
        else:
            keep = energy > inside.ravel()[order[removed - 1]]
        keep[:h, :w] = keep_inside.reshape(inside.shape)
        return keep

    def restricted(self, region: np.ndarray) -> PatchWaveletCoefficients:
        """The coefficients with the details outside ``region`` removed (section 5.2).

        ``region`` is a boolean map of the map's shape. A detail is kept when its odd sample
        (:meth:`detail_positions`) lies in the region: its detail and its analysed feature stay,
        the others become zero and ``-1``.
        """
        region = np.asarray(region, dtype=bool)
        if region.shape != self.shape:
            raise ValueError(f"region must have the map's shape {self.shape}, got {region.shape}")
        details, features = {}, {}
        for (level, axis), d in self.details.items():
            rows, cols = self.detail_positions(level, axis)
            keep = region[np.ix_(rows, cols)]
            details[(level, axis)] = np.where(keep[..., None], d, 0.0)
            if (level, axis) in self.features:
                features[(level, axis)] = np.where(keep[..., None], self.features[(level, axis)], -1)
        return PatchWaveletCoefficients(
            self.coarse.copy(), self.top_level, details, self.grid_boundary, features
        )

    def locally_thresholded(
        self, ratio: float, *, per_level: bool = False, smoothing: float = 4.0
    ) -> PatchWaveletCoefficients:
        """Thresholding of the local detail energy: :meth:`restricted` to :meth:`kept_region`.

        Removes the details of the share ``ratio`` of the map where the input deviates least
        from the exemplar's own predictions, as whole regions rather than scattered samples;
        invert with ``restore=True`` (:meth:`PatchLifting.inverse_step`). ``ratio = 0``
        rebuilds the analysed map exactly, ``ratio = 1`` is the pure synthesis of
        :meth:`thresholded` at 1 (``docs/methods/patch_wavelet.md``, "Deviations").
        """
        return self.restricted(self.kept_region(ratio, per_level=per_level, smoothing=smoothing))

    def max_norm(self) -> float:
        """Largest detail magnitude over all levels and directions (the ``max d_j`` of Fig. 7)."""
        return max((float(n.max()) for n in self.norms().values() if n.size), default=0.0)

    def thresholded(self, ratio: float, *, per_level: bool = False) -> PatchWaveletCoefficients:
        """Hard thresholding that removes the small details (section 5.2).

        A detail is kept iff ``||d|| > ratio * max``; the maximum is global, or per level
        (both directions) with ``per_level=True``. ``ratio = 1`` removes every detail (pure
        synthesis from the coarse features), ``ratio = 0`` removes none. (The paper's
        displayed formula keeps the small ones; its text and Fig. 7 remove them,
        ``docs/methods/patch_wavelet.md``.)
        """
        if not 0.0 <= ratio <= 1.0:
            raise ValueError(f"ratio must be in [0, 1], got {ratio!r}")
        norms = self.norms()
        global_max = self.max_norm()
        out, features = {}, {}
        for (level, axis), d in self.details.items():
            if per_level:
                top = max(float(norms[(level, a)].max()) for a in (0, 1) if (level, a) in norms)
            else:
                top = global_max
            keep = norms[(level, axis)] > ratio * top
            out[(level, axis)] = np.where(keep[..., None], d, 0.0)
            if (level, axis) in self.features:
                features[(level, axis)] = np.where(keep[..., None], self.features[(level, axis)], -1)
        return PatchWaveletCoefficients(self.coarse.copy(), self.top_level, out, self.grid_boundary, features)

    def magnitudes(self) -> np.ndarray:
        """Detail magnitudes packed like an orthogonal wavelet transform (Fig. 7).

        Level ``j`` with ``a = n_h / 2^j`` and ``b = n_w / 2^j`` puts the horizontal-pair
        magnitudes (``a x b``) in ``[0:a, b:2b]`` and the vertical-pair magnitudes
        (``a x 2b``) in ``[a:2a, 0:2b]``; the coarse corner stays 0. The result has the shape
        ``(n_h, n_w)`` of the map (``n x n`` for a square one).
        """
        n_h, n_w = self.shape
        out = np.zeros((n_h, n_w))
        norms = self.norms()
        for level in range(1, self.top_level + 1):
            a, b = n_h // 2**level, n_w // 2**level
            if (level, 1) in norms:
                out[0:a, b : 2 * b] = norms[(level, 1)]
            if (level, 0) in norms:
                out[a : 2 * a, 0 : 2 * b] = norms[(level, 0)]
        return out
