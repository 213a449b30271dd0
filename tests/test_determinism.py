"""Same seed, same texture, whatever the number of threads (DESIGN.md convention 4)."""

import os
import subprocess
import sys

import texsyn

SCRIPT = r"""
import hashlib, sys
import numpy as np
import texsyn
sys.path.insert(0, {tests!r})
from conftest import FAST_PARAMS
layers = np.stack([texsyn.data.exemplar(n, size=40) for n in ("grass", "gravel", "brick")], -1)
big = np.stack([texsyn.data.exemplar(n, size=64) for n in ("grass", "gravel", "brick")], -1)
for name in sorted(texsyn.METHODS):
    params = dict(FAST_PARAMS[name])
    exemplar, shape = layers, (48, 44)
    if name == "efros_leung":  # large enough for multi-threaded matrix products
        params["window_size"] = 11
        exemplar, shape = big, (56, 60)
    out = texsyn.synthesize(exemplar, name, shape, rng=11, **params)
    print(name, hashlib.sha256(out.tobytes()).hexdigest())
frames = [f.image for f in texsyn.animate(big, 3, (32, 32), rng=4, n_iterations=3)]
print("animate", hashlib.sha256(np.stack(frames).tobytes()).hexdigest())
modified = texsyn.modify(layers[:32, :32], big, 0.1)
print("modify", hashlib.sha256(modified.tobytes()).hexdigest())
"""


def run_with_threads(threads):
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        env.pop(var, None)
        if threads is not None:
            env[var] = str(threads)
    tests = os.path.dirname(__file__)
    code = SCRIPT.format(tests=tests)
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return dict(line.split() for line in done.stdout.strip().splitlines())


def test_same_seed_same_output_with_one_thread_and_default_threads():
    single = run_with_threads(1)
    default = run_with_threads(None)
    assert set(single) == set(texsyn.METHODS) | {"modify", "animate"}
    assert single == default
