"""Shared fixtures: small real textures every scikit-image user has (no files needed)."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

import texsyn

sys.path.insert(0, os.path.dirname(__file__))
import sabotage


def pytest_addoption(parser):
    parser.addoption(
        "--method-tests",
        metavar="NAME",
        help="run only the tests marked @pytest.mark.method(NAME) (used by the sabotage harness)",
    )


def pytest_configure(config):
    config.addinivalue_line("markers", "method(name, ...): tests of what makes method NAME that method")
    config.addinivalue_line("markers", "slow: long meta-tests (sabotage harness), not in the default run")
    installed = sabotage.install()
    if installed:
        sys.stderr.write(f"texsyn tests: {installed}\n")


def pytest_collection_modifyitems(config, items):
    name = config.getoption("--method-tests")
    if not name:
        return
    keep, drop = [], []
    for item in items:
        names = {arg for mark in item.iter_markers("method") for arg in mark.args}
        (keep if name in names else drop).append(item)
    config.hook.pytest_deselected(items=drop)
    items[:] = keep


@pytest.fixture(scope="session")
def grey_exemplar() -> np.ndarray:
    """A 40x40 crop of scikit-image's brick texture, float32 in [0, 1]."""
    return texsyn.data.exemplar("brick", size=40)


@pytest.fixture(scope="session")
def colour_exemplar() -> np.ndarray:
    """A 40x40 colour texture with correlated channels, mixed from scikit-image's grass,
    gravel and brick (a greenish, natural-looking colour distribution)."""
    layers = np.stack([texsyn.data.exemplar(name, size=40) for name in ("grass", "gravel", "brick")], axis=-1)
    mix = np.array([[0.5, 0.3, 0.2], [0.6, 0.3, 0.1], [0.2, 0.2, 0.6]])
    return (layers @ mix.T).astype(np.float32)


#: small settings that keep every method fast in the test suite
FAST_PARAMS = {
    "quilting": {"patch_size": 12},
    "efros_leung": {"window_size": 5},
    "heeger_bergen": {"n_scales": 2, "n_iterations": 2},
    "random_phase": {},
    "lg": {"patch_size": 10, "n_neighbors": 8},
    "clg": {"patch_size": 10, "n_neighbors": 8},
    "rclg": {"patch_size": 10, "n_neighbors": 8},
    "mslg": {"patch_size": 8, "n_neighbors": 8, "n_scales": 2},
    "cwt": {"levels": 2, "seed": "random"},
    "wei_levoy": {"levels": 2, "window": 5, "parent_window": 3},
    "sparse": {
        "patch_size": 6,
        "step": 3,
        "n_scales": 2,
        "n_atoms": 24,
        "ksvd_iterations": 2,
        "n_outer": 3,
        "n_inner": 3,
    },
    "patch_wavelet": {"sigma": (0.0, 0.2)},
    "grouplets": {"n_iterations": 3, "levels": 2, "grouplet_levels": 3},
    "portilla_simoncelli": {"n_scales": 2, "n_iterations": 3},
}


@pytest.fixture(params=sorted(texsyn.METHODS))
def method_name(request) -> str:
    return request.param


def fast_method(name: str):
    return texsyn.make_method(name, **FAST_PARAMS.get(name, {}))
