"""``fixed_order`` from any thread: BLAS runs one thread in the thread that entered it.

OpenBLAS 0.3.31 keeps a thread's count apart from the process's once the process has set it:
a thread other than the first setter kept computing with the default count, so a method run
by a web server's or a batch worker's thread gave other bytes than the command line.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from texsyn.ops import linalg


def _product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    with linalg.fixed_order():
        return a @ b


def test_a_product_in_fixed_order_has_the_same_bytes_on_every_thread(monkeypatch):
    monkeypatch.setattr(linalg, "worker_count", lambda: 2)
    rng = np.random.default_rng(0)
    # a shape whose two-thread OpenBLAS product differs in the last bits from one thread's
    a, b = rng.standard_normal((256, 64)), rng.standard_normal((64, 700))
    reference = _product(a, b)  # the main thread, as the command line
    big_a = rng.standard_normal((600, 64))
    big_reference = linalg.matmul(big_a, b)
    with ThreadPoolExecutor(max_workers=1) as other:
        assert np.array_equal(other.submit(_product, a, b).result(), reference)
        assert np.array_equal(other.submit(linalg.matmul, big_a, b).result(), big_reference)
        mapped = other.submit(linalg.parallel_map, lambda _: _product(a, b), range(4)).result()
    assert all(np.array_equal(product, reference) for product in mapped)
    assert np.array_equal(_product(a, b), reference)
