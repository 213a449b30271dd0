"""The sabotage harness: each method's tests must fail when its output is broken on purpose.

For every (method, sabotage) pair a fresh pytest process runs the tests marked
``@pytest.mark.method(NAME)`` with ``TEXSYN_SABOTAGE`` set (see ``tests/sabotage.py``) and
must end with failures (exit status 1). Marked ``slow``: ``python -m pytest -m slow`` runs it
(``.ci/run`` does, after the default suite); see ``docs/testing.md``.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import texsyn

CASES = (
    [(name, kind) for name in sorted(texsyn.METHODS) for kind in ("shuffle", "blur")]
    + [("modify", "shuffle"), ("modify", "blur")]
    + [("animate", kind) for kind in ("shuffle", "blur", "freeze", "independent", "stripes")]
)


def run_method_tests(name: str, kind: str | None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("TEXSYN_SABOTAGE", None)
    env.pop("TEXSYN_SABOTAGE_METHOD", None)
    if kind is not None:
        env.update(TEXSYN_SABOTAGE=kind, TEXSYN_SABOTAGE_METHOD=name)
    tests = os.path.dirname(__file__)
    command = [
        sys.executable,
        "-m",
        "pytest",
        tests,
        "-q",
        "-x",
        "-p",
        "no:cacheprovider",
        "-m",
        "not slow",
        f"--method-tests={name}",
    ]
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted({name for name, _ in CASES}))
def test_method_has_tests_that_pass_unsabotaged(name):
    done = run_method_tests(name, None)
    assert done.returncode == 0, done.stdout[-3000:]


@pytest.mark.slow
@pytest.mark.parametrize("name, kind", CASES, ids=[f"{n}-{k}" for n, k in CASES])
def test_sabotage_is_caught(name, kind):
    done = run_method_tests(name, kind)
    # 1: tests ran and some failed; 5 (no tests) or 0 (all passed) mean the method is unguarded
    assert done.returncode == 1, (
        f"{kind} of {name} was not caught (exit {done.returncode}):\n{done.stdout[-3000:]}"
    )
