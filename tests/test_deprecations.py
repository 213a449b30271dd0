"""Deprecations reach users (issue 17): under Python's default filters a DeprecationWarning is
shown only when it names ``__main__``, so every front door names the caller's line; a
deprecated value warns once, at construction, and ``fit`` never changes a parameter. Also:
a command line whose reader left ends quietly."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import texsyn
from texsyn.cli import EXIT_BROKEN_PIPE
from texsyn.errors import InputError
from texsyn.methods import LG, EfrosLeung, RandomPhase

#: one line each; the script runs them in order, each on its own line number
FRONT_DOORS = {
    "synthesize": 'texsyn.synthesize(ex, "efros_leung", shape=(6, 6), rng=0, window_size=5, epsilon=0.2)',
    "make_method": 'texsyn.make_method("cwt", levels=2, epsilon=0.5)',
    "constructor": "texsyn.methods.EfrosLeung(epsilon=0.1)",
    "modify": "texsyn.modify(ex, ex, 0.5, min_width=4, random_state=3)",
    "animate": "next(texsyn.animate(ex, n_frames=1, rng=0, iterations=1))",
    "load": "texsyn.load(saved, epsilon=0.3)",
    "overlap fraction": 'texsyn.make_method("lg", patch_size=6, overlap=0.5).fit(ex).sample((8, 8), rng=0)',
    "overlap fraction, class": "texsyn.methods.RCLG(patch_size=6, overlap=0.5)",
}

SCRIPT = """\
import tempfile
import texsyn
from texsyn.methods import Grouplets

class OldGrouplets(Grouplets):  # a renamed parameter of animate's method
    deprecated_params = {"iterations": "n_iterations"}

texsyn.METHODS["grouplets"] = OldGrouplets
ex = texsyn.data.exemplar("gravel", size=16)
saved = texsyn.save(texsyn.make_method("efros_leung", window_size=5).fit(ex), tempfile.mkdtemp() + "/m.npz")
"""


@pytest.fixture(scope="module")
def default_filters_stderr(tmp_path_factory):
    """The script run by a fresh interpreter under the default warning filters: (path, lines, stderr)."""
    path = tmp_path_factory.mktemp("user") / "user_script.py"
    lines = {}
    text = SCRIPT
    for name, call in FRONT_DOORS.items():
        lines[name] = text.count("\n") + 1
        text += call + "\n"
    path.write_text(text)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONWARNINGS", "PYTHONDEVMODE")}
    proc = subprocess.run(
        [sys.executable, str(path)], capture_output=True, text=True, env=env, timeout=300, check=False
    )
    assert proc.returncode == 0, proc.stderr
    return path, lines, proc.stderr


@pytest.mark.parametrize("door", sorted(FRONT_DOORS))
def test_a_deprecation_names_the_users_line_under_default_filters(default_filters_stderr, door):
    path, lines, stderr = default_filters_stderr
    shown = [line for line in stderr.splitlines() if "DeprecationWarning" in line]
    assert any(line.startswith(f"{path}:{lines[door]}: DeprecationWarning: ") for line in shown), stderr
    assert not any("texsyn" in line.split(": DeprecationWarning")[0] for line in shown), stderr


def test_every_deprecation_of_the_script_is_shown_once(default_filters_stderr):
    _, lines, stderr = default_filters_stderr
    shown = [
        line.split(": DeprecationWarning")[0] for line in stderr.splitlines() if "DeprecationWarning" in line
    ]
    assert len(shown) == len(set(shown)) == len(lines), stderr


def test_the_warning_names_the_caller_in_process():
    with pytest.warns(DeprecationWarning) as seen:
        EfrosLeung(epsilon=0.1)
        texsyn.make_method("efros_leung", epsilon=0.1)
        LG(patch_size=8, overlap=0.25)
    assert [w.filename for w in seen] == [__file__] * 3


def test_a_subclass_calling_the_parents_init_warns_once():
    class Renamed(RandomPhase):
        deprecated_params = {"periodic": "periodic_component"}

        def __init__(self, **params):
            super().__init__(**params)

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        method = Renamed(periodic=False)
    assert method.periodic_component is False
    assert [str(w.message) for w in seen] == [
        "parameter 'periodic' of method 'random_phase' is deprecated; use 'periodic_component'"
    ]
    assert seen[0].filename == __file__


@pytest.mark.parametrize("name", ["lg", "clg", "rclg"])
def test_an_overlap_fraction_warns_once_at_construction_and_stays_as_given(name):
    ex = texsyn.data.exemplar("gravel", size=24)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        method = texsyn.make_method(name, patch_size=8, overlap=0.5)
        assert len(seen) == 1 and seen[0].category is DeprecationWarning
        assert "(overlap=4 for 0.5 of 8)" in str(seen[0].message) and seen[0].filename == __file__
        before = method.get_params()
        image = method.fit(ex).sample((16, 16), rng=0)
        method.sample((16, 16), rng=1)
    assert len(seen) == 1, [str(w.message) for w in seen]
    assert method.get_params() == before and before["overlap"] == 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        pixels = texsyn.make_method(name, patch_size=8, overlap=4).fit(ex)
    assert pixels.get_params()["overlap"] == 4
    np.testing.assert_array_equal(image, pixels.sample((16, 16), rng=0))


@pytest.mark.parametrize("overlap", [1.0, 1.5, -0.5, 8, 0])
def test_an_overlap_that_is_neither_a_fraction_nor_pixels_of_the_patch_is_refused_at_fit(overlap):
    method = texsyn.make_method("lg", patch_size=8, overlap=overlap)
    with pytest.raises(InputError, match="overlap"):
        method.fit(texsyn.data.exemplar("gravel", size=24))


def test_mslg_has_no_overlap_parameter():
    with pytest.raises(InputError, match="unknown parameter 'overlap'"):
        texsyn.make_method("mslg", overlap=0.5)


@pytest.mark.parametrize("args", [["methods"], [], ["--help"], ["--version"], ["synth", "--help"]])
def test_a_closed_stdout_ends_the_command_line_quietly(args):
    read, write = os.pipe()
    os.close(read)  # the reader left before the first line (texsyn methods | head -0)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "texsyn.cli", *args],
            stdout=write,
            stderr=subprocess.PIPE,
            timeout=120,
            check=False,
        )
    finally:
        os.close(write)
    assert (proc.returncode, proc.stderr) == (EXIT_BROKEN_PIPE, b"")


def test_comparison_progress_is_reported_through_the_reporter():
    from texsyn.report import run_comparison

    seen = []
    run_comparison(
        texsyn.data.exemplar("gravel", size=16), ["random_phase", "no_such"], seeds=2, callback=seen.append
    )
    assert [(p.stage, p.done, p.total) for p in seen] == [("methods", d, 4) for d in (1, 2, 4)]
