"""The skewness and kurtosis steps of the Portilla–Simoncelli projections.

J. Portilla, E. Simoncelli, IJCV 40(1), 2000, section 4 (the reference code's ``modskew`` and
``modkurt``): a band is moved along the gradient of its skewness or kurtosis, with a step
``l`` found as a root of a polynomial whose coefficients are moments of the band. The other
projections are in :mod:`texsyn.models.portilla_projections`, which re-exports these steps
(``docs/methods/portilla_simoncelli.md``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["FLAT_VARIANCE", "impose_kurtosis", "impose_skewness", "is_flat"]


def _closest_lambda(num, den, target, power, scale):
    """The step (0 included) whose moment ratio ``num / den^power`` is closest to ``target``."""
    grid = np.concatenate([[0.0], np.linspace(-4.0, 4.0, 4001) * scale])
    values = (
        np.polynomial.polynomial.polyval(grid, num) / np.polynomial.polynomial.polyval(grid, den) ** power
    )
    return grid[np.argmin(np.abs(values - target))]


#: variance, relative to ``max(1, mean^2)``, below which a band is flat: its skewness and
#: kurtosis are rounding noise (a one-pixel or constant image), and are left alone
FLAT_VARIANCE = 1e-20


def is_flat(variance: float, mean: float) -> bool:
    """Whether a band of this variance and mean has no shape to impose moments on."""
    return not variance > FLAT_VARIANCE * max(1.0, float(mean) ** 2)


# Polynomials in the step ``l`` as coefficients, lowest degree first. These helpers do the
# arithmetic of ``numpy.polynomial.Polynomial`` (same trimming of zero leading coefficients,
# same ``np.convolve`` products, same companion matrix and eigenvalue solver, same identity
# map of the default domain) without its per-object overhead: the skewness and kurtosis
# steps run a few thousand times per synthesis, and the objects cost more than the
# arithmetic. ``tests/test_portilla_fast_paths.py`` checks that the results are the same bits.
_ZERO, _ONE = np.float64(0.0), np.float64(1.0)  # the default domain's map: off + scl x


def _trim(c: np.ndarray) -> np.ndarray:
    """``c`` without its trailing zero coefficients (at least one kept), as ``polyutils.trimseq``."""
    if len(c) == 0 or c[-1] != 0:
        return c
    for i in range(len(c) - 1, -1, -1):
        if c[i] != 0:
            break
    return c[: i + 1]


def _series(c) -> np.ndarray:
    """A trimmed float64 copy of ``c``, as ``polyutils.as_series([c])[0]`` (a 1-D float64
    array, the usual case, is trimmed and copied without the conversions)."""
    if type(c) is np.ndarray and c.dtype == np.float64 and c.ndim == 1:
        return _trim(c).copy()
    return np.array(_trim(np.array(c, ndmin=1, copy=None)), dtype=np.float64, copy=True)


def _poly_val(c: np.ndarray, x):
    """``Polynomial(c)(x)``: the domain's identity map, then Horner's scheme (``polyval``)."""
    x = _ZERO + _ONE * np.asanyarray(x)
    c0 = c[-1] + x * 0
    for i in range(2, len(c) + 1):
        c0 = c[-i] + c0 * x
    return c0


def _poly_roots(c) -> np.ndarray:
    """``Polynomial(c).roots()``: eigenvalues of the companion matrix, sorted (``polyroots``)."""
    c = _series(c)
    if len(c) < 2:
        roots = np.array([], dtype=c.dtype)
    elif len(c) == 2:
        roots = np.array([-c[0] / c[1]])
    else:
        n = len(c) - 1
        companion = np.zeros((n, n), dtype=c.dtype)
        companion.reshape(-1)[n :: n + 1] = 1
        companion[:, -1] -= c[:-1] / c[-1]
        roots = _eigenvalues(companion)
        roots.sort()
    return _ZERO + _ONE * roots


try:  # the compiled routine behind numpy.linalg.eigvals (its wrapper costs more than the call)
    from numpy.linalg import _umath_linalg as _linalg_routines
except ImportError:  # pragma: no cover - another NumPy layout: the public function
    _linalg_routines = None  # type: ignore[assignment]


def _eigenvalues(matrix: np.ndarray) -> np.ndarray:
    """``numpy.linalg.eigvals(matrix)`` of a real square matrix: the same LAPACK call and the
    same result (complex, or real when every imaginary part is zero), without the wrapper's
    checks where they pass; a matrix they refuse, or LAPACK's failure to converge, goes to
    ``eigvals`` itself, which raises as it does."""
    if _linalg_routines is None or not math.isfinite(matrix.sum()):  # (a finite sum: all finite)
        return np.linalg.eigvals(matrix)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore", under="ignore"):
        values = _linalg_routines.eigvals(matrix, signature="d->D")
    if not math.isfinite(values.real.sum()):  # no convergence (its values are NaN): eigvals raises
        return np.linalg.eigvals(matrix)
    return values.real if not values.imag.any() else values


def _roots(c: list) -> tuple[list, list]:
    """The real and imaginary parts of :func:`_poly_roots` of the coefficients ``c``, as lists."""
    roots = _poly_roots(c)
    return roots.real.tolist(), (roots.imag.tolist() if roots.dtype.kind == "c" else [0.0] * roots.size)


# The step solver below does the arithmetic of ``numpy.polynomial.Polynomial`` on lists of
# floats: sums, differences, products by a number, derivatives and Horner's scheme are the
# same operations on the same numbers one at a time (a product by a number as ``np.convolve``
# makes it, ``0 + a b``); products of two polynomials and the roots stay NumPy's
# (``np.convolve``, the companion matrix's eigenvalues), so the results are the same bits
# (``tests/test_portilla_fast_paths.py``) for a quarter of the calls into NumPy.


def _trimmed(c: list) -> list:
    """``c`` without its trailing zero coefficients (at least one kept), as :func:`_trim`."""
    n = len(c)
    while n > 1 and c[n - 1] == 0:
        n -= 1
    return c[:n] if n < len(c) else c


def _times(c1: list, c2: list) -> list:
    """The product of two polynomials, untrimmed (``np.convolve`` of the trimmed factors)."""
    return np.convolve(_trimmed(c1), _trimmed(c2)).tolist()


def _scaled(factor: float, c: list) -> list:
    """``Polynomial([factor]) * Polynomial(c)``: each product as ``np.convolve`` makes it."""
    return _trimmed([0.0 + factor * v for v in _trimmed(c)])


def _minus(c1: list, c2: list) -> list:
    """``Polynomial(c1) - Polynomial(c2)`` (:func:`_poly_sub`)."""
    c1, c2 = _trimmed(c1), _trimmed(c2)
    if len(c1) > len(c2):
        return _trimmed([a - b for a, b in zip(c1, c2)] + c1[len(c2) :])
    out = [-b for b in c2]
    for i, a in enumerate(c1):
        out[i] += a
    return _trimmed(out)


def _derivative(c: list) -> list:
    """``Polynomial(c).deriv()`` of untrimmed coefficients (:func:`_poly_der`)."""
    if len(c) <= 1:
        return [c[0] * 0] if c else []
    return [j * c[j] for j in range(1, len(c))]


def _value(c: list, x: float) -> float:
    """``Polynomial(c)(x)`` of one number (:func:`_poly_val`)."""
    x = 0.0 + 1.0 * x
    value = c[-1] + x * 0
    for i in range(2, len(c) + 1):
        value = c[-i] + value * x
    return value


def _sign(x: float) -> float:
    """``np.sign(x)``."""
    return float(x > 0) - float(x < 0) if x == x else float(x)


def _monotone_interval(num, den, power) -> tuple[float, float]:
    """The interval around ``l = 0`` on which ``num(l) / den(l)^(power/2)`` is monotone.

    Its ends are the critical points nearest to 0 on either side (``-inf``/``inf`` where
    there is none): the roots of ``num' den - (power/2) num den'``, the numerator of the
    ratio's derivative.
    """
    num = [float(v) for v in num]
    den = [float(v) for v in den]
    derivative = _minus(
        _trimmed(_times(_derivative(num), den)), _trimmed(_times(_scaled(power / 2.0, num), _derivative(den)))
    )
    real = _real_roots(derivative)
    below = [r for r in real if r < 0]
    above = [r for r in real if r > 0]
    return (np.float64(max(below)) if below else -np.inf), (np.float64(min(above)) if above else np.inf)


def _real_roots(c: list) -> list:
    """The real roots of ``c`` (imaginary part below ``1e-6`` of the real one, or of 1), in
    :func:`_poly_roots`'s order."""
    real, imag = _roots(c)
    return [r for r, i in zip(real, imag) if abs(i) < 1e-6 * max(1.0, abs(r))]


def _solve_lambda(coeffs_num, coeffs_den, target, power):
    """The step ``l`` of ``modskew`` / ``modkurt`` (Portilla and Simoncelli 2000, section 4).

    The root of ``num(l)^2 = target^2 den(l)^power`` (sign of num = sign of target) of smallest
    ``|l|`` within the interval around 0 where the moment ratio is monotone
    (:func:`_monotone_interval`). A root beyond the ratio's nearest extremum exists when the
    ratio turns back (a skewed band asked for a lower kurtosis than its extremum); reaching it
    moves ``l g`` far enough to dominate the band (a cubic of its values: the skewness lost,
    the high-pass energy multiplied), so the extremum nearest the target is taken instead,
    as the reference code saturates an unreachable moment. ``None`` when the target is
    unreachable and the ratio has no extremum.
    """
    num = [float(v) for v in coeffs_num]
    den = [float(v) for v in coeffs_den]
    if power == 3:  # skewness: num / den^1.5 = t  ->  num^2 - t^2 den^3 = 0, sign(num) = sign(t)
        cube = np.convolve(np.convolve(_trimmed(den), _trimmed(den)), _trimmed(den)).tolist()
        poly = _minus(_times(num, num), _scaled(target**2, cube))
    else:  # kurtosis: num / den^2 = t  ->  num - t den^2 = 0
        poly = _minus(num, _scaled(target, _times(den, den)))
    real = _real_roots(poly)
    if power == 3 and target != 0:
        wanted = _sign(target)
        real = [r for r in real if _sign(_value(num, r)) == wanted]
    low, high = _monotone_interval(num, den, power)
    real = [r for r in real if low <= r <= high]
    if real:
        return np.float64(min(real, key=abs))
    ends = np.array([end for end in (low, high) if np.isfinite(end)])
    if ends.size == 0:
        return None
    num_array, den_array = np.array(num), np.array(den)
    ratio = _poly_val(num_array, ends) / _poly_val(den_array, ends) ** (power / 2.0)
    return ends[np.argmin(np.abs(ratio - target))]


def _power_means(x: np.ndarray, mean: float, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """The means of ``d^k``, ``k = 0 .. 2 rows``, ``d = x - mean``, and the powers ``d^1 ..
    d^rows`` as rows.

    The powers are built once and every power sum the skewness (``rows = 3``: degree 6) or
    kurtosis (``rows = 6``: degree 12) step needs is one dot product of two of them, instead
    of a few passes over the band per moment.
    """
    n = x.size
    powers = np.empty((rows, n))
    d = np.subtract(x.reshape(-1), mean, out=powers[0])
    np.multiply(d, d, out=powers[1])
    for k in range(2, rows):
        np.multiply(powers[k - 1], d, out=powers[k])
    sums = np.empty(2 * rows + 1)
    sums[0] = n
    sums[1] = d.sum()
    for k in range(2, 2 * rows + 1):  # d^k = d^(k // 2) d^(k - k // 2)
        sums[k] = np.dot(powers[k // 2 - 1], powers[k - k // 2 - 1])
    return sums / n, powers


def _expect(poly: np.ndarray, means: np.ndarray) -> float:
    """The mean of a polynomial of the band, ``sum_k poly[k] mean(d^k)``."""
    return float(np.dot(poly, means[: poly.size]))


def _evaluate(coef: np.ndarray, powers: np.ndarray, shape: tuple) -> np.ndarray:
    """``coef[0] + coef[1] d + coef[2] d^2 + ...`` from the rows of :func:`_power_means`."""
    out = coef[1:] @ powers[: coef.size - 1]
    out += coef[0]
    return out.reshape(shape)


def impose_skewness(x: np.ndarray, target: float) -> np.ndarray:
    """Move ``x`` along the skewness gradient until its skewness is ``target`` (``modskew``).

    ``y = x + l (d^2 - (m3/m2) d - m2)`` (``d`` = centred ``x``): the direction is orthogonal to
    the mean and to ``d``, so mean and variance change only to second order and are restored.
    The skewness of ``y`` is a ratio of polynomials in ``l`` whose coefficients are moments;
    the root of smallest ``|l|`` is taken.

    Every moment is a combination of the power sums of ``d`` up to degree 6, computed at
    once (:func:`_power_means`), and the result is a quadratic of ``d``
    (``docs/methods/portilla_simoncelli.md``, "Performance": the same step up to rounding).
    """
    mean = x.mean()
    means, powers = _power_means(x, mean, 3)
    m2 = means[2]
    if is_flat(m2, mean):
        return x
    m3 = means[3]
    g = np.array([-m2, -m3 / m2, 1.0])  # g = d^2 - (m3 / m2) d - m2
    g2 = np.convolve(g, g)
    g3 = np.convolve(g2, g)
    num = [m3, 3 * _expect(np.concatenate([[0.0, 0.0], g]), means)]
    num += [3 * _expect(np.concatenate([[0.0], g2]), means), _expect(g3, means)]
    den = [m2, 2 * _expect(np.concatenate([[0.0], g]), means), _expect(g2, means)]
    lam = _solve_lambda(num, den, target, 3)
    if lam is None:  # unreachable target: go to the closest reachable skewness instead
        lam = _closest_lambda(num, den, target, 1.5, np.sqrt(m2 / max(den[2], 1e-300)))
    y = lam * g
    y[1] += 1.0  # y = d + lam g
    y *= np.sqrt(m2 / _expect(np.convolve(y, y), means))
    y[0] += mean
    return _evaluate(y, powers, x.shape)


def impose_kurtosis(x: np.ndarray, target: float) -> np.ndarray:
    """Move ``x`` along the kurtosis gradient until its kurtosis is ``target`` (``modkurt``).

    ``y = x + l g`` with ``g`` the part of ``d^3`` orthogonal to ``1, d, d^2`` (normal equations
    from the moments), so that mean, variance and skewness change only to second order; the
    mean and variance are restored exactly.

    Every moment is a combination of the power sums of ``d`` up to degree 12, computed at
    once (:func:`_power_means`), and the result is a cubic of ``d``
    (``docs/methods/portilla_simoncelli.md``, "Performance": the same step up to rounding).
    """
    mean = x.mean()
    means, powers = _power_means(x, mean, 6)
    m = [1.0, 0.0, *means[2:7]]
    if is_flat(m[2], mean):
        return x
    gram = np.array([[m[i + j] for j in range(3)] for i in range(3)])
    rhs = np.array([m[3], m[4], m[5]])
    try:
        coef = np.linalg.solve(gram, rhs)
    except np.linalg.LinAlgError:
        coef = np.linalg.lstsq(gram, rhs, rcond=None)[0]
    g = np.array([-coef[0], -coef[1], -coef[2], 1.0])  # g = d^3 - coef[0] - coef[1] d - coef[2] d^2
    g2 = np.convolve(g, g)
    g3 = np.convolve(g2, g)
    num = [m[4], 4 * _expect(np.concatenate([[0.0, 0.0, 0.0], g]), means)]
    num += [6 * _expect(np.concatenate([[0.0, 0.0], g2]), means)]
    num += [4 * _expect(np.concatenate([[0.0], g3]), means), _expect(np.convolve(g2, g2), means)]
    den = [m[2], 2 * _expect(np.concatenate([[0.0], g]), means), _expect(g2, means)]
    lam = _solve_lambda(num, den, target, 4)
    if lam is None:
        lam = _closest_lambda(num, den, target, 2.0, np.sqrt(m[2] / max(den[2], 1e-300)))
    y = lam * g
    y[1] += 1.0  # y = d + lam g
    y[0] -= _expect(y, means)  # centred
    y *= np.sqrt(m[2] / _expect(np.convolve(y, y), means))
    y[0] += mean
    return _evaluate(y, powers, x.shape)
