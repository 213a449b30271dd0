"""Gaussian models estimated from a few samples: sampling and conditioning in m x m form.

Spec 00, section 8, and spec 05, sections 4.3-4.5. With ``m`` sample vectors ``X`` of
dimension ``D`` (``m << D``), the centred matrix ``P = (X - mu)^T`` (``D x m``) gives the
covariance ``Sigma = P P^T / (m - 1)``, which is never formed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg

__all__ = ["LocalGaussian", "local_gaussian"]


@dataclass(frozen=True)
class LocalGaussian:
    """A Gaussian ``N(mu, P P^T / (m - 1))`` estimated from ``m`` samples.

    Attributes
    ----------
    mean : ndarray, shape (D,)
    factor : ndarray, shape (D, m)
        The centred samples ``P`` divided by ``sqrt(m - 1)``, so that ``Sigma = F F^T``.
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
    ) -> np.ndarray:
        """Sample (or, with ``rng=None``, the mean of) the unknown entries given the known ones.

        The model is regularised, ``Gamma = Sigma + sigma^2 I``; with ``A = F[S]``,
        ``B = F[R]`` (``S`` unknown, ``R`` known entries) and ``M = B^T B + sigma^2 I_m``,
        Woodbury's identity gives the conditional law of the unknown entries exactly:

        * mean ``mu_S + A M^{-1} B^T (y0 - mu_R)``,
        * covariance ``sigma^2 (I + A M^{-1} A^T)``, sampled as
          ``sigma (z1 + A C^{-T} z2)`` with ``M = C C^T``.

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

        Returns
        -------
        ndarray, shape (D - k,)
            The unknown entries ``S`` (in the order of ``np.flatnonzero(~known)``).

        References
        ----------
        Raad, Desolneux, Morel (2016), section 3.1, eqs. (4)-(6).
        """
        f_known = self.factor[known]
        f_free = self.factor[~known]
        m = self.factor.shape[1]
        gram = f_known.T @ f_known + (sigma**2) * np.eye(m)
        chol = linalg.cho_factor(gram, lower=True)
        beta = linalg.cho_solve(chol, f_known.T @ (values - self.mean[known]))
        mean = self.mean[~known] + f_free @ beta
        if rng is None:
            return mean
        z1 = rng.standard_normal(f_free.shape[0])
        z2 = rng.standard_normal(m)
        # C^{-T} z2 solves C^T x = z2 with C lower triangular
        x = linalg.solve_triangular(chol[0], z2, lower=True, trans="T")
        return mean + sigma * (z1 + f_free @ x)


def local_gaussian(samples: np.ndarray) -> LocalGaussian:
    """Estimate the local Gaussian of ``m >= 2`` sample vectors (rows of ``samples``).

    The unbiased sample covariance around the samples' mean (Raad et al. 2016, eq. 1,
    resolution R1 of spec 05).
    """
    x = np.asarray(samples, dtype=np.float64)
    m = x.shape[0]
    if m < 2:
        raise ValueError(f"a local Gaussian needs at least 2 samples, got {m}")
    mean = x.mean(axis=0)
    return LocalGaussian(mean=mean, factor=(x - mean).T / np.sqrt(m - 1))
