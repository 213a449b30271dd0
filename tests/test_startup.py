"""Start-up cost: what ``import texsyn`` and one command load (issue 20, ``docs/performance.md``).

Each check runs a fresh interpreter and lists the modules it ended with, so that a new
eager import of numba, scikit-learn, scipy's heavy submodules or another method's module is
caught where it is added, whatever the machine's speed (no timing here: ``benchmarks/``
measures the seconds).
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import texsyn
from texsyn.io import write_image
from texsyn.methods import METHODS, MethodRegistry
from texsyn.ops.jit import LazyKernel, jit, prange

#: what no command should load unless its method needs it
HEAVY = (
    "numba",
    "sklearn",
    "scipy.ndimage",
    "scipy.sparse",
    "skimage",
    "texsyn.report",
    "texsyn.metrics",
    "importlib.metadata",
    "texsyn.web",
    "fastapi",
    "uvicorn",
)


def loaded_after(code: str) -> set[str]:
    """The modules loaded by a fresh interpreter after running ``code``."""
    script = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_import_texsyn_loads_no_method_numba_scikit_learn_or_report():
    modules = loaded_after("import texsyn")
    assert not {m for m in HEAVY if m in modules}
    assert not {m for m in modules if m.startswith("texsyn.methods.") and m.count(".") == 2} - {
        "texsyn.methods._base",
        "texsyn.methods._params",
        "texsyn.methods._memory",
        "texsyn.methods._deprecation",
    }


def test_the_version_literal_is_the_installed_version():
    """``texsyn._version`` is a literal (no ``importlib.metadata`` at start-up) that the build reads."""
    from importlib.metadata import version

    assert texsyn.__version__ == version("texsyn")


def test_synth_with_quilting_loads_quilting_only(tmp_path):
    exemplar, out = tmp_path / "ex.png", tmp_path / "q.png"
    write_image(exemplar, np.random.default_rng(0).random((32, 32, 3)))
    args = ["synth", str(exemplar), "-m", "quilting", "--size", "48x48", "--seed", "1", "-q", "-o", str(out)]
    modules = loaded_after(f"from texsyn.cli import main\nassert main({args!r}) == 0")
    assert out.exists()
    assert not {m for m in HEAVY if m in modules}
    methods = {m for m in modules if m.startswith("texsyn.methods.") and not m.split(".")[-1].startswith("_")}
    assert methods == {"texsyn.methods.quilting"}
    assert "texsyn.cli.animation" not in modules and "texsyn.cli.comparison" not in modules


def test_synth_with_wei_levoy_loads_no_scipy_filters_or_linear_algebra(tmp_path):
    """The Gaussian pyramid is NumPy's, and numba finds its BLAS without ``scipy.linalg``."""
    exemplar, out = tmp_path / "ex.png", tmp_path / "w.png"
    write_image(exemplar, np.random.default_rng(0).random((32, 32, 3)))
    args = [
        "synth",
        str(exemplar),
        "-m",
        "wei_levoy",
        "--size",
        "24x24",
        "-p",
        "levels=2",
        "--seed",
        "1",
        "-q",
    ]
    modules = loaded_after(f"from texsyn.cli import main\nassert main({args + ['-o', str(out)]!r}) == 0")
    assert out.exists() and "numba" in modules
    assert not {"scipy.ndimage", "scipy.special", "scipy.fft", "scipy.linalg"} & modules


def test_a_compiled_kernel_leaves_scipy_linalg_whole():
    """numba's BLAS check finds ``cython_blas`` loaded alone; a later ``import scipy.linalg``
    still binds it to its package (``scipy.linalg.cython_blas`` is public)."""
    code = (
        "from texsyn.ops.ranks import sorted_keys\n"  # a compiled kernel, loaded
        "import numpy as np, sys\n"
        "sorted_keys(np.arange(6.0).reshape(2, 3))\n"
        "assert 'scipy.linalg' not in sys.modules\n"
        "import scipy.linalg, scipy.linalg.cython_blas\n"
        "assert scipy.linalg.cython_blas.__pyx_capi__['dgemm']\n"
    )
    assert "numba" in loaded_after(code)


def test_registry_names_match_their_classes():
    assert list(METHODS)[:2] == ["quilting", "efros_leung"]
    for name in METHODS:
        assert METHODS[name].name == name
    assert "nope" not in METHODS
    with pytest.raises(KeyError):
        METHODS["nope"]


def test_registry_entries_can_be_replaced_and_removed():
    registry = MethodRegistry({"quilting": "Quilting"})
    original = registry["quilting"]

    class Other(original):  # type: ignore[misc, valid-type]
        name = "other"

    registry["other"] = Other
    registry["quilting"] = Other
    assert list(registry) == ["quilting", "other"] and registry["quilting"] is Other
    del registry["other"]
    assert len(registry) == 1 and "other" not in registry


def test_lazy_exports_resolve_to_the_defining_modules():
    assert texsyn.Frame is texsyn.methods.grouplets.Frame
    assert texsyn.load is texsyn.persistence.load
    assert "Frame" in dir(texsyn)
    with pytest.raises(AttributeError):
        texsyn.not_a_name  # noqa: B018


@jit()
def _scaled(x, factor):
    return x * factor


@jit(parallel=True)
def _row_sums(values):
    out = np.zeros(values.shape[0])
    for i in prange(values.shape[0]):
        out[i] = _scaled(values[i].sum(), 2.0)
    return out


def test_lazy_kernel_compiles_on_first_call_and_matches_python():
    values = np.arange(12.0).reshape(3, 4)
    kernel = LazyKernel(_row_sums.py_func, parallel=True)
    assert "not compiled" in repr(kernel)
    expected = _row_sums.py_func(values)
    assert np.array_equal(kernel(values), expected)
    assert "not compiled" not in repr(kernel)
    assert np.array_equal(_row_sums(values), expected)
