"""Same seed, same bytes, whatever the number of threads (docs/determinism.md).

Every method, ``modify`` and ``animate`` run in fresh processes with 1, 2, 4 and the default
number of threads (OpenMP, BLAS, numba); all must print the same hashes. Which BLAS kernels
change their rounding with the thread count depends on the processor, so where the
processor can run them the same runs are repeated with OpenBLAS forced to other kernels
(``OPENBLAS_CORETYPE``): a machine then tests more than its own kernel.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import texsyn

SCRIPT = r"""
import hashlib, sys
import numpy as np
import texsyn
from texsyn.ops.linalg import matmul
sys.path.insert(0, {tests!r})
from conftest import FAST_PARAMS

def digest(array):
    return hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()

layers = np.stack([texsyn.data.exemplar(n, size=40) for n in ("grass", "gravel", "brick")], -1)
big = np.stack([texsyn.data.exemplar(n, size=64) for n in ("grass", "gravel", "brick")], -1)
for name in sorted(texsyn.METHODS):
    params = dict(FAST_PARAMS[name])
    exemplar, shape = layers, (48, 44)
    if name == "efros_leung":  # large enough for multi-threaded matrix products
        params["window_size"] = 11
        exemplar, shape = big, (56, 60)
    if name == "portilla_simoncelli":  # statistics over more than 10^4 pixels (threaded dot products)
        exemplar, shape = big, (128, 120)
    out = texsyn.synthesize(exemplar, name, shape, rng=11, **params)
    print(name, digest(out))
    if name == "efros_leung":  # grown on a torus (docs/tiling.md)
        print(name + "-tileable", digest(texsyn.synthesize(exemplar, name, shape, rng=11, tileable=True, **params)))
frames = [f.image for f in texsyn.animate(big, 3, (32, 32), rng=4, n_iterations=3)]
print("animate", digest(np.stack(frames)))
modified = texsyn.modify(layers[:32, :32], big, 0.1)
print("modify", digest(modified))
rng = np.random.default_rng(0)
a, b = rng.standard_normal((700, 300)), rng.standard_normal((300, 500))
print("matmul", digest(matmul(a, b)) + digest(matmul(a.astype(np.float32), b.astype(np.float32))))
from texsyn.metrics import ps_statistics
print("ps_statistics", digest(ps_statistics(big[..., 0], n_scales=3).vector()))
"""

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def _openblas_kernels_to_force() -> list[str]:
    """Other OpenBLAS kernels this processor can run (none off x86-64 or without AVX2)."""
    if platform.machine().lower() not in ("x86_64", "amd64") or "OPENBLAS_CORETYPE" in os.environ:
        return []  # a machine that pins a kernel (e.g. to avoid a faulty one) keeps it
    try:
        import threadpoolctl

        if not any(i.get("internal_api") == "openblas" for i in threadpoolctl.threadpool_info()):
            return []
        with open("/proc/cpuinfo") as fh:
            flags = next((line.split(":", 1)[1].split() for line in fh if line.startswith("flags")), [])
    except (OSError, ImportError):
        return []
    return ["Haswell"] if {"avx2", "fma"} <= set(flags) else []


KERNELS = [None] + _openblas_kernels_to_force()
THREADS = [None, 1, 2, 4]
SETTINGS = [
    (kernel, threads)
    for kernel in KERNELS
    for threads in THREADS
    if kernel is None or threads in (None, 1, 2)
]


def _run(setting: tuple[str | None, int | None]) -> dict[str, str]:
    kernel, threads = setting
    env = dict(os.environ)
    for var in THREAD_VARIABLES:
        env.pop(var, None)
        if threads is not None:
            env[var] = str(threads)
    if kernel is not None:
        env["OPENBLAS_CORETYPE"] = kernel
    code = SCRIPT.format(tests=os.path.dirname(__file__))
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return dict(line.split() for line in done.stdout.strip().splitlines())


@pytest.fixture(scope="module")
def hashes() -> dict:
    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(zip(SETTINGS, pool.map(_run, SETTINGS)))


def _name(setting) -> str:
    kernel, threads = setting
    return f"{kernel or 'native'}-{threads or 'default'}-threads"


@pytest.mark.parametrize("setting", [s for s in SETTINGS if s[1] is not None], ids=_name)
def test_same_bytes_as_with_the_default_thread_count(hashes, setting):
    kernel, _ = setting
    reference = hashes[(kernel, None)]
    assert set(reference) == set(texsyn.METHODS) | {
        "modify",
        "animate",
        "matmul",
        "ps_statistics",
        "efros_leung-tileable",
    }
    differing = sorted(name for name in reference if hashes[setting][name] != reference[name])
    assert not differing, f"{_name(setting)} changes the output of {differing}"


def test_fixed_order_restores_the_callers_blas_threads():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    from texsyn.ops.linalg import fixed_order

    before = {
        i["filepath"]: i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"
    }
    with fixed_order():
        inside = {
            i["filepath"]: i["num_threads"]
            for i in threadpoolctl.threadpool_info()
            if i["user_api"] == "blas"
        }
        with fixed_order():
            pass
        again = {
            i["filepath"]: i["num_threads"]
            for i in threadpoolctl.threadpool_info()
            if i["user_api"] == "blas"
        }
    after = {
        i["filepath"]: i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"
    }
    assert set(inside.values()) <= {1} and again == inside
    assert after == before


def test_matmul_equals_numpy_and_does_not_depend_on_the_workers(monkeypatch):
    from texsyn.ops import linalg

    rng = np.random.default_rng(1)
    a, b = rng.standard_normal((1000, 70)), rng.standard_normal((70, 90))
    parallel = linalg.matmul(a, b)
    np.testing.assert_allclose(parallel, a @ b, rtol=1e-12, atol=1e-12)
    monkeypatch.setattr(linalg, "worker_count", lambda: 1)
    assert np.array_equal(linalg.matmul(a, b), parallel)
    np.testing.assert_allclose(linalg.matmul(a, b[:, 0]), a @ b[:, 0], rtol=1e-12, atol=1e-12)


def _product_in_child(queue) -> None:
    from texsyn.ops.linalg import matmul

    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((600, 80)), rng.standard_normal((80, 3000))
    queue.put(bool(np.allclose(matmul(a, b), a @ b)))


def test_matmul_works_in_a_process_forked_after_using_it():
    import multiprocessing

    from texsyn.ops.linalg import matmul

    rng = np.random.default_rng(2)
    matmul(rng.standard_normal((600, 80)), rng.standard_normal((80, 3000)))  # starts the pool
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_product_in_child, args=(queue,))
    child.start()
    child.join(60)
    hung = child.is_alive()
    if hung:
        child.kill()
    assert not hung, "a forked child hangs on the parent's thread pool"
    assert queue.get(timeout=5) is True


def test_matmul_tiles_the_columns_too():
    from texsyn.ops import linalg

    rng = np.random.default_rng(4)
    a, b = rng.standard_normal((40, 300)), rng.standard_normal((300, 3 * linalg.BLOCK_COLUMNS + 5))
    np.testing.assert_allclose(linalg.matmul(a, b), a @ b, rtol=1e-12, atol=1e-12)
