"""``fixed_order`` from any thread: BLAS runs one thread while any thread is inside it.

OpenBLAS's (pthreads) thread count is one value for the whole process. threadpoolctl sets it
only from its "controlling thread" (the first that set it, while it lives) and ignores the
others: a thread other than the main one entering after the main thread had run anything
kept two threads, so a method run by a web server's or a batch worker's thread gave other
bytes than the command line (``texsyn.ops.linalg._enter``, ``docs/determinism.md``).
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


#: run in a fresh process (the count an earlier test left does not hide a fault): two
#: threads inside at once, the first leaving while the second computes, then the last
#: caller leaving from a thread other than the main one
_SERVER_THREADS = """
import json, threading
from concurrent.futures import ThreadPoolExecutor
import numpy as np
from threadpoolctl import ThreadpoolController
from texsyn.ops import linalg

def counts():
    return [lib.num_threads for lib in ThreadpoolController().lib_controllers if lib.user_api == "blas"]

def product(a, b):
    with linalg.fixed_order():
        return a @ b

rng = np.random.default_rng(0)
a, b = rng.standard_normal((256, 64)), rng.standard_normal((64, 700))
before = counts()
reference = product(a, b)  # the main thread first, as a server that ran something
first_inside, second_inside, first_left = threading.Event(), threading.Event(), threading.Event()

def first():
    with linalg.fixed_order():
        first_inside.set()
        second_inside.wait(30)
    first_left.set()

def second():
    first_inside.wait(30)
    with linalg.fixed_order():
        second_inside.set()
        first_left.wait(30)
        return counts(), bool(np.array_equal(a @ b, reference))

with ThreadPoolExecutor(max_workers=2) as threads:
    left = threads.submit(first)
    inside_counts, same_bytes = threads.submit(second).result(timeout=60)
    left.result(timeout=60)
after_two_threads = counts()

entered, done = threading.Event(), threading.Event()
def last():
    with linalg.fixed_order():
        entered.set()
        done.wait(30)
with linalg.fixed_order():  # the main thread enters first and leaves first
    thread = threading.Thread(target=last)
    thread.start()
    entered.wait(30)
done.set()
thread.join(30)
print(json.dumps({"before": before, "inside": inside_counts, "same_bytes": same_bytes,
                  "after_two_threads": after_two_threads, "after_last_on_a_thread": counts()}))
"""


def test_threads_inside_at_once_keep_one_blas_thread_and_the_last_leaver_restores_it():
    """A count set per thread and given back on leaving was the whole process's: when the
    first of two server threads left, the second computed with two BLAS threads. A count
    restored through threadpoolctl from a thread other than its controlling one was ignored:
    the process kept one BLAS thread after texsyn had returned."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    source = str(Path(linalg.__file__).parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([source, os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(
        [sys.executable, "-c", _SERVER_THREADS], capture_output=True, text=True, timeout=120, env=env
    )
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert found["inside"] and set(found["inside"]) == {1}
    assert found["same_bytes"]
    assert found["after_two_threads"] == found["before"]
    assert found["after_last_on_a_thread"] == found["before"]
