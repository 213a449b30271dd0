"""Locally Gaussian patch models (Raad, Desolneux & Morel 2016): what LG, CLG, RCLG and MSLG fit.

Two models, both built once by ``fit`` and never changed by ``sample``
(``docs/architecture.md``, "Fitted state"):

- :class:`PatchSource`: one exemplar scale seen as a bank of ``n x n`` patches, with an
  exact FFT search that finds the ``m`` patches nearest to what is already synthesised
  (the search's cache of energy terms belongs to each ``sample`` call, not to the source);
- :class:`LocalGaussian`: the Gaussian ``N(mu, Sigma)`` estimated from those ``m`` patches
  (section 2.1, eq. 1), sampled and conditioned in ``m x m`` form (section 3, eqs. 4-8).

With ``m`` sample vectors ``X`` of dimension ``D`` (``m << D``), the centred matrix
``P = (X - mu)^T`` (``D x m``) gives the covariance ``Sigma = P P^T / (m - 1)``, which is
never formed. See ``docs/methods/local_gaussian.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import linalg

from ..ops.search import FFTPatchSearch, knn_select

__all__ = ["LocalGaussian", "PatchSource", "local_gaussian"]


@dataclass(frozen=True)
class LocalGaussian:
    """A Gaussian ``N(mu, P P^T / (m - 1))`` estimated from ``m`` samples.

    Attributes
    ----------
    mean : ndarray, shape (D,)
    factor : ndarray, shape (D, m)
        The centred samples ``P`` divided by ``sqrt(m - 1)``, so that ``Sigma = F F^T``.

    Examples
    --------
    >>> g = local_gaussian(np.array([[0.0, 1.0], [2.0, 3.0]]))
    >>> g.mean.tolist(), g.sample(np.random.default_rng(0)).shape
    ([1.0, 2.0], (2,))
    """

    mean: np.ndarray
    factor: np.ndarray

    @property
    def mean_std(self) -> float:
        """Mean per-entry standard deviation ``(1/D) sum_i sqrt(Sigma_ii)`` (Raad et al. Fig. 2)."""
        return float(np.mean(np.sqrt(np.sum(self.factor**2, axis=1))))

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        """``mu + F g`` with ``g ~ N(0, I_m)``: exact covariance, ``O(m D)``."""
        return self.mean + self.factor @ rng.standard_normal(self.factor.shape[1])

    def conditional(
        self,
        known: np.ndarray,
        values: np.ndarray,
        sigma: float,
        rng: np.random.Generator | None,
        *,
        looseness: float = 0.0,
    ) -> np.ndarray:
        """Sample (or, with ``rng=None``, the mean of) the unknown entries given the known ones.

        The model is regularised, ``Gamma = Sigma + sigma^2 I``; with ``A = F[S]``,
        ``B = F[R]`` (``S`` unknown, ``R`` known entries) and ``M = B^T B + s^2 I_m``,
        Woodbury's identity gives the conditional law of the unknown entries exactly:

        * mean ``mu_S + A M^{-1} B^T (y0 - mu_R)``,
        * covariance ``sigma^2 I + s^2 A M^{-1} A^T``, sampled as
          ``sigma z1 + s A C^{-T} z2`` with ``M = C C^T``.

        With ``looseness = 0``, ``s = sigma`` (the paper's eqs. 4-6). Otherwise the known
        values are read as noisy observations of the patch, ``s^2 = max(sigma^2, looseness
        tr(B^T B) / m)``: a multiple of the mean eigenvalue of ``B^T B``. The ``k`` known
        values are explained by ``m << k`` neighbours, so with the paper's tiny ``sigma`` they
        fix all ``m`` degrees of freedom of the local Gaussian (its posterior covariance
        vanishes, nothing is sampled) and the regression carries the overlap's blur into
        the new patch (``docs/methods/local_gaussian.md``, "Conditioning").
        Cost ``O(m^2 D + m^3)`` instead of the ``O(D^3)`` of the D x D formulas.

        Parameters
        ----------
        known : ndarray of bool, shape (D,)
            The entries ``R`` whose values are given.
        values : ndarray, shape (k,)
            The given values ``y0`` on ``R`` (in the order of ``np.flatnonzero(known)``).
        sigma : float
            Regularisation, ``sigma > 0``.
        rng : numpy.random.Generator or None
            ``None`` returns the conditional mean (the most probable patch, eq. 5).
        looseness : float
            How loosely the unknown entries follow the known ones (0: the paper's exact
            conditioning).

        Returns
        -------
        ndarray, shape (D - k,)
            The unknown entries ``S`` (in the order of ``np.flatnonzero(~known)``).

        References
        ----------
        Raad, Desolneux, Morel (2016), section 3.1, eqs. (4)-(6).
        """
        return self.posterior(known, values, sigma, rng, looseness=looseness)[~known]

    def posterior(
        self,
        known: np.ndarray,
        values: np.ndarray,
        sigma: float,
        rng: np.random.Generator | None,
        *,
        looseness: float = 0.0,
    ) -> np.ndarray:
        """:meth:`conditional` for every entry: the known ones too, as the model explains them.

        With ``looseness > 0`` the known values are noisy observations, so the posterior's
        known entries differ from ``values``; :func:`texsyn.methods.single_scale_gaussian.conditional_patch`
        carries that difference into the free entries near the overlap. Same draws as
        :meth:`conditional` (``z1`` for every entry, then ``z2``).

        Returns
        -------
        ndarray, shape (D,)
        """
        f_known = self.factor[known]
        f_all = self.factor
        m = self.factor.shape[1]
        gram = f_known.T @ f_known
        noise = max(float(sigma) ** 2, float(looseness) * float(np.trace(gram)) / m)
        gram[np.diag_indices(m)] += noise
        chol = linalg.cho_factor(gram, lower=True)
        beta = linalg.cho_solve(chol, f_known.T @ (values - self.mean[known]))
        mean = self.mean + f_all @ beta
        if rng is None:
            return mean
        z1 = np.zeros(f_all.shape[0])
        z1[~known] = rng.standard_normal(int(np.count_nonzero(~known)))
        z2 = rng.standard_normal(m)
        # C^{-T} z2 solves C^T x = z2 with C lower triangular
        x = linalg.solve_triangular(chol[0], z2, lower=True, trans="T")
        return mean + sigma * z1 + np.sqrt(noise) * (f_all @ x)


def local_gaussian(samples: np.ndarray) -> LocalGaussian:
    """Estimate the local Gaussian of ``m >= 2`` sample vectors (rows of ``samples``).

    The unbiased sample covariance around the samples' own mean (Raad et al. 2016, section
    2.1, eq. 1; ``docs/methods/local_gaussian.md``).

    Raises
    ------
    ValueError
        With fewer than 2 samples.
    """
    x = np.asarray(samples, dtype=np.float64)
    m = x.shape[0]
    if m < 2:
        raise ValueError(f"a local Gaussian needs at least 2 samples, got {m}")
    mean = x.mean(axis=0)
    factor = (x - mean).T  # scaled in place: the same values and layout, one array fewer
    factor /= np.sqrt(m - 1)
    return LocalGaussian(mean=mean, factor=factor)


@dataclass(frozen=True)
class PatchSource:
    """One exemplar scale as a bank of ``size x size`` patches and an exact search over it.

    ``search`` compares queries with ``search_image`` (the scale itself, or the scale stacked
    with its low-pass for MSLG's joint distance, Raad et al. 2016 eq. 14); the neighbour
    patches themselves are read from ``values``.

    Attributes
    ----------
    search : FFTPatchSearch
        Exact weighted SSD against every exemplar position.
    values : ndarray, shape (H, W, C)
        Where the neighbour patches are read from.
    size : int
        Patch side ``n``.
    """

    search: FFTPatchSearch
    values: np.ndarray
    size: int

    @classmethod
    def build(cls, search_image: np.ndarray, values: np.ndarray, size: int) -> PatchSource:
        """The search over ``search_image`` and the patch bank ``values`` (same height and width)."""
        return cls(FFTPatchSearch(search_image, (size, size)), values, int(size))

    @property
    def anchor_shape(self) -> tuple[int, int]:
        """Number of patch positions along each axis."""
        return self.search.anchor_shape

    @property
    def n_anchors(self) -> int:
        """Number of exemplar patches."""
        rows, cols = self.anchor_shape
        return rows * cols

    def gather(self, flat_anchors: np.ndarray) -> np.ndarray:
        """Patches at flat anchor indices as rows ``(m, n*n*C)`` (C-order of ``(n, n, C)``)."""
        windows = sliding_window_view(self.values, (self.size, self.size), axis=(0, 1))  # a view
        rows, cols = np.unravel_index(flat_anchors, self.anchor_shape)
        patches = windows[rows, cols]  # (m, C, n, n)
        return np.ascontiguousarray(patches.transpose(0, 2, 3, 1)).reshape(len(rows), -1)

    def nearest(
        self, query: np.ndarray, weights: np.ndarray | None, m: int, *, energies: dict | None = None
    ) -> np.ndarray:
        """Flat anchors of the ``m`` exemplar windows nearest to ``query`` (tie-safe).

        ``energies`` is the caller's cache for :meth:`FFTPatchSearch.distances
        <texsyn.ops.search.FFTPatchSearch.distances>`: one dict per synthesis and per source,
        so that the source itself is never changed.
        """
        return knn_select(self.search.distances(query, weights, energies=energies), m)

    def neighbour_gaussian(
        self, query: np.ndarray, weights: np.ndarray | None, m: int, *, energies: dict | None = None
    ) -> LocalGaussian:
        """The local Gaussian of the ``m`` patches nearest to ``query`` (section 2.1; Algorithm 2,
        lines 5-6).

        Parameters
        ----------
        query : ndarray, shape (n, n, C') or (n, n)
            What is known of the patch (compared with ``search_image``).
        weights : ndarray or None
            Pixel (or per-channel) weights of the distance; ``None`` compares every entry.
        m : int
            Number of neighbours.
        energies : dict, optional
            See :meth:`nearest`.

        Examples
        --------
        >>> ex = np.random.default_rng(0).random((8, 8, 1))
        >>> source = PatchSource.build(ex, ex, 3)
        >>> gauss = source.neighbour_gaussian(ex[:3, :3], None, 4)
        >>> gauss.mean.shape, gauss.factor.shape
        ((9,), (9, 4))
        """
        return local_gaussian(self.gather(self.nearest(query, weights, m, energies=energies)))
