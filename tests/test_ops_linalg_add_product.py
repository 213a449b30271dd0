"""``texsyn.ops.linalg.add_product``: ``out += a @ b`` in one BLAS call, the same bits."""

from __future__ import annotations

import numpy as np
import pytest

from texsyn.ops import linalg


def _cases():
    rng = np.random.default_rng(3)
    for m, k, n in [(12, 12, 65536), (12, 24, 16384), (4, 8, 4096), (3, 64, 8192), (5, 7, 40000)]:
        a = rng.standard_normal((m, k)).astype(np.float32)
        b = rng.standard_normal((k, n)).astype(np.float32) * np.float32(10.0) ** rng.integers(-3, 3, (k, 1))
        out = rng.standard_normal((m, n)).astype(np.float32)
        yield a, b, out


@pytest.mark.parametrize("case", range(5))
def test_the_sum_has_the_bits_of_numpy_add_after_the_product(case):
    a, b, out = list(_cases())[case]
    expected = out.copy()
    expected += a @ b
    got = out.copy()
    with linalg.fixed_order():
        result = linalg.add_product(got, a, b)
    assert result is got
    assert got.tobytes() == expected.tobytes()


def test_rows_of_one_array_and_strided_operands():
    # the Portilla-Simoncelli regressions: ``out`` the first rows, ``b`` the others of one array
    rng = np.random.default_rng(4)
    rows = rng.standard_normal((36, 1 << 14)).astype(np.float32)
    mix = rng.standard_normal((12, 24)).astype(np.float32)
    expected = rows[:12].copy()
    expected += mix @ rows[12:]
    out = rows[:12]
    linalg.add_product(out, mix, rows[12:])
    assert out.tobytes() == expected.tobytes()
    wide = rng.standard_normal((24, 2 << 14)).astype(np.float32)[:, ::2]  # not row-major: NumPy's way
    target = rng.standard_normal((12, 1 << 14)).astype(np.float32)
    expected = target.copy()
    expected += mix @ wide
    assert linalg.add_product(target, mix, wide).tobytes() == expected.tobytes()


def test_overlapping_or_other_arrays_go_through_numpy(monkeypatch):
    calls = []
    sgemm = linalg.cblas_sgemm()
    if sgemm is None:
        pytest.skip("no cblas_sgemm in this NumPy")
    monkeypatch.setattr(linalg, "cblas_sgemm", lambda: calls.append(1) or sgemm)
    rng = np.random.default_rng(5)
    a = rng.standard_normal((8, 8)).astype(np.float32)
    square = rng.standard_normal((8, 1 << 14)).astype(np.float32)
    expected = square.copy()
    expected += a @ square
    linalg.add_product(square, a, square)  # ``out`` is ``b``: NumPy's product, then the sum
    assert square.tobytes() == expected.tobytes()
    double = rng.standard_normal((8, 1 << 14))
    expected = double.copy()
    expected += a.astype(np.float64) @ double
    other = double.copy()
    assert linalg.add_product(double, a.astype(np.float64), other).tobytes() == expected.tobytes()
    assert calls == []  # neither reached BLAS directly
    linalg.add_product(np.zeros((8, 1 << 14), np.float32), a, square)
    assert calls == [1]


@pytest.mark.parametrize("m, k, n", [(1, 3, 1 << 16), (1, 6, 1 << 16), (1 << 16, 3, 1)])
def test_a_row_or_a_column_has_the_bits_of_numpys_vector_product(m, k, n):
    # NumPy multiplies a row or a column with sgemv, whose sums are not sgemm's
    rng = np.random.default_rng(6)
    a = rng.standard_normal((m, k)).astype(np.float32)
    b = rng.standard_normal((k, n)).astype(np.float32)
    out = rng.standard_normal((m, n)).astype(np.float32)
    with linalg.fixed_order():
        expected = out.copy()
        expected += a @ b
        linalg.add_product(out, a, b)
    assert out.tobytes() == expected.tobytes()
