"""Round 1's public forms that the redesign replaced keep working, deprecated (issue 17).

Each old form warns with a :class:`DeprecationWarning` that names the caller's line, and gives
exactly what the form that replaced it gives (the same arrays, the same progress calls).
"""

from __future__ import annotations

import dataclasses
import importlib
import pickle
import warnings

import numpy as np
import pytest

import texsyn
from texsyn.drivers.alternating import alternate_projections
from texsyn.drivers.raster import grow_pixels
from texsyn.methods.portilla_simoncelli import ps_synthesis
from texsyn.models.grouplets import GroupletModel, HistogramTargets
from texsyn.models.patch_wavelet import PatchWaveletTransform
from texsyn.models.portilla import ps_statistics
from texsyn.ops.nonparametric import NonParametricSampler, grow_texture
from texsyn.ops.progress import Reporter


@pytest.fixture(scope="module")
def small():
    return texsyn.data.exemplar("brick", size=24).astype(np.float64)


# ---------------------------------------------------------------------- Efros-Leung growth
def test_grow_texture_is_grow_pixels_with_the_round1_callback(small):
    old_calls, new_calls = [], []
    with pytest.warns(DeprecationWarning, match="grow_texture is deprecated") as caught:
        old = grow_texture(
            small,
            (14, 12),
            window=5,
            epsilon=0.2,
            rng=np.random.default_rng(3),
            callback=lambda filled, total: old_calls.append((filled, total)),
        )
    assert caught[0].filename == __file__  # the warning names the caller
    reporter = Reporter(lambda p: new_calls.append((p.done, p.total)), "pixels", 14 * 12)
    new = grow_pixels(
        NonParametricSampler(small, 5),
        (14, 12),
        tolerance=0.2,
        rng=np.random.default_rng(3),
        reporter=reporter,
    )
    np.testing.assert_array_equal(old[0], new[0])
    np.testing.assert_array_equal(old[1], new[1])
    assert old_calls == new_calls and old_calls[-1] == (14 * 12, 14 * 12)


def test_sampler_grow_is_grow_pixels(small):
    sampler = NonParametricSampler(small, 5)
    with pytest.warns(DeprecationWarning, match="NonParametricSampler.grow is deprecated") as caught:
        old = sampler.grow((10, 13), seed_block=(2, 3, 4, 5), max_error=0.2, rng=np.random.default_rng(1))
    assert caught[0].filename == __file__
    new = grow_pixels(sampler, (10, 13), seed_block=(2, 3, 4, 5), max_error=0.2, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(old[0], new[0])
    np.testing.assert_array_equal(old[1], new[1])


# ---------------------------------------------------------------------- grouplet model
def test_round1_grouplet_model_call_learns_the_same_frozen_model(small):
    from texsyn.methods.grouplets import GroupletModel as exported  # round 1's import path

    assert exported is GroupletModel
    params = {"levels": 2, "grouplet_levels": 2, "sigma": 3.0}
    with pytest.warns(DeprecationWarning, match="from_exemplar") as caught:
        old = exported(small, **params)
    assert caught[0].filename == __file__
    with pytest.warns(DeprecationWarning, match="from_exemplar"):
        by_keyword = GroupletModel(exemplar=small, **params)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # the current forms warn about nothing
        new = GroupletModel.from_exemplar(small, **params)
        copied = dataclasses.replace(new)  # the fields' constructor
        unpickled = pickle.loads(pickle.dumps(new))
    for model in (old, by_keyword, copied, unpickled):
        assert isinstance(model, GroupletModel)
        for name in ("flow", "coherence", "band_values", "pixel_values"):
            np.testing.assert_array_equal(getattr(model, name), getattr(new, name))
            assert not getattr(model, name).flags.writeable
        assert (model.levels, model.grouplet_levels, model.shape) == (2, 2, small.shape)
    with pytest.raises(dataclasses.FrozenInstanceError):
        old.levels = 3  # type: ignore[misc]


def test_grouplet_project_is_the_alternating_driver_with_project_once(small):
    model = GroupletModel.from_exemplar(small, levels=2, grouplet_levels=2)
    flow = model.flow[:16, :20]
    transform = model.transform(flow)
    noise = model.noise((16, 20), np.random.default_rng(0))
    old_calls, new_calls = [], []
    with pytest.warns(DeprecationWarning, match="GroupletModel.project is deprecated") as caught:
        old = model.project(noise, transform, 3, lambda k, f: old_calls.append((k, f.copy())))
    assert caught[0].filename == __file__
    targets = model.targets(16 * 20)
    new = alternate_projections(
        noise,
        lambda f, _k: model.project_once(f, transform, targets),
        3,
        reporter=Reporter(lambda p: new_calls.append((p.done, p.image.copy())), "iteration", 3),
        preview=lambda f: f,
    )
    np.testing.assert_array_equal(old, new)
    assert [k for k, _ in old_calls] == [k for k, _ in new_calls] == [1, 2, 3]
    for (_, a), (_, b) in zip(old_calls, new_calls):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(old_calls[-1][1], old)


def test_grouplet_targets_unpack_as_round1_tuple(small):
    model = GroupletModel.from_exemplar(small, levels=1, grouplet_levels=1)
    targets = model.targets(100)
    assert isinstance(targets, HistogramTargets)
    with pytest.warns(DeprecationWarning, match="HistogramTargets") as caught:
        bands, pixels = targets
    assert caught[0].filename == __file__
    assert bands is targets.bands and pixels is targets.pixels
    with pytest.warns(DeprecationWarning, match="HistogramTargets"):
        assert targets[1] is targets.pixels


# ---------------------------------------------------------------------- Portilla-Simoncelli
def test_ps_synthesis_round1_callback_is_the_reporter(small):
    target = ps_statistics(small, n_scales=2, n_orientations=3, lags=2)
    initial = np.random.default_rng(4).standard_normal((1, 16, 16))
    old_calls, new_calls = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        alias = importlib.import_module("texsyn.ops.portilla")
    assert alias.ps_synthesis is ps_synthesis
    with pytest.warns(DeprecationWarning, match="callback") as caught:
        old = alias.ps_synthesis(
            target, initial, 2, lags=2, callback=lambda k, x: old_calls.append((k, x.copy()))
        )
    assert caught[0].filename == __file__
    reporter = Reporter(lambda p: new_calls.append((p.done, p.image.copy())), "iteration", 2)
    new = ps_synthesis(target, initial, 2, lags=2, reporter=reporter, preview=lambda x: x)
    np.testing.assert_array_equal(old, new)
    assert [k for k, _ in old_calls] == [k for k, _ in new_calls] == [1, 2]
    for (_, a), (_, b) in zip(old_calls, new_calls):
        np.testing.assert_array_equal(a, b)
    with pytest.warns(DeprecationWarning), pytest.raises(TypeError, match="not both"):
        ps_synthesis(target, initial, 1, callback=print, reporter=reporter)


# ---------------------------------------------------------------------- patch-valued wavelets
def test_patch_wavelet_round1_callbacks(small):
    transform = PatchWaveletTransform(small, min_width=4, lle_points=256, exemplar_boundary="symmetric")
    rng = np.random.default_rng(2)
    coords = np.stack([rng.integers(0, 24, (8, 8)), rng.integers(0, 24, (8, 8))], axis=-1)
    records, forward_calls, inverse_calls = [], [], []
    new = transform.forward(coords, report=Reporter(records.append, "levels", 3))
    with pytest.warns(DeprecationWarning, match=r"forward\(callback=") as caught:
        old = transform.forward(coords, callback=lambda done, levels: forward_calls.append((done, levels)))
    assert caught[0].filename == __file__
    assert forward_calls == [(p.done, p.total) for p in records] == [(1, 3), (2, 3), (3, 3)]
    assert old.keys() == new.keys()
    np.testing.assert_array_equal(old.coarse, new.coarse)
    for key in new.details:
        np.testing.assert_array_equal(old.details[key], new.details[key])

    records.clear()
    rebuilt = transform.inverse(new, report=Reporter(records.append, "levels", 3))
    with pytest.warns(DeprecationWarning, match=r"inverse\(callback=") as caught:
        again = transform.inverse(
            new, callback=lambda done, levels, T: inverse_calls.append((done, levels, T))
        )
    assert caught[0].filename == __file__
    np.testing.assert_array_equal(again, rebuilt)
    assert (
        [(d, n) for d, n, _ in inverse_calls]
        == [(p.done, p.total) for p in records]
        == [(1, 3), (2, 3), (3, 3)]
    )
    assert [T.shape[:2] for _, _, T in inverse_calls] == [(2, 2), (4, 4), (8, 8)]
    np.testing.assert_array_equal(inverse_calls[-1][2], rebuilt)


def test_moved_modules_are_reached_as_attributes_with_one_warning_at_the_users_line(tmp_path):
    """``texsyn.ops.dtcwt`` (no import statement) and ``from texsyn.io import save_fitted`` warn
    once each, naming the user's script, under Python's default warning filters."""
    import subprocess
    import sys

    script = tmp_path / "old_user.py"
    script.write_text(
        "import texsyn\n"
        "print(texsyn.ops.dtcwt.DTCWT.__name__, texsyn.ops.steerable.SteerablePyramid.__name__)\n"
        "from texsyn.io import save_fitted\n"
    )
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["DTCWT", "SteerablePyramid"]
    lines = [line for line in done.stderr.splitlines() if "DeprecationWarning" in line]
    assert len(lines) == 3, done.stderr
    assert all(line.startswith(f"{script}:") for line in lines), done.stderr
    assert sum("texsyn.io.save_fitted" in line for line in lines) == 1
