"""Saved models (``docs/persistence.md``): one versioned format for every method.

save -> load -> sample gives the bytes of sampling the saved model, for every method; bad
files are refused with one clear :class:`~texsyn.errors.InputError`.
"""

from __future__ import annotations

import io
import json
import os
import time
import tracemalloc
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

import texsyn
from conftest import fast_method
from texsyn.errors import InputError, InputFileNotFoundError, MemoryLimitError, OutputExistsError
from texsyn.persistence import ADDED_PARAMS, DEFAULT, FORMAT_VERSION


@pytest.fixture(scope="module")
def saved_random_phase(tmp_path_factory, colour_exemplar):
    model = texsyn.make_method("random_phase").fit(colour_exemplar)
    path = texsyn.save(model, tmp_path_factory.mktemp("models") / "rp.npz")
    return model, path


def test_save_load_sample_gives_identical_bytes(method_name, colour_exemplar, tmp_path):
    model = fast_method(method_name).fit(colour_exemplar)
    path = texsyn.save(model, tmp_path / f"{method_name}.npz")
    loaded = texsyn.load(path)
    assert type(loaded) is type(model)
    assert loaded.get_params() == model.get_params()
    a = model.sample_with_map((24, 28), rng=5)
    b = loaded.sample_with_map((24, 28), rng=5)
    assert a.image.tobytes() == b.image.tobytes()
    if a.source_map is None:
        assert b.source_map is None
    else:
        assert a.source_map.tobytes() == b.source_map.tobytes()


def test_the_header_names_format_version_method_and_params(saved_random_phase):
    model, path = saved_random_phase
    with np.load(path, allow_pickle=False) as data:
        header = json.loads(str(data["header"]))
        assert data["exemplar"].shape == model.exemplar_.shape
    assert header["format"] == "texsyn-model"
    assert header["format_version"] == FORMAT_VERSION
    assert header["method"] == "random_phase"
    assert header["params"] == model.get_params()
    assert header["texsyn_version"] == texsyn.__version__


def test_sparse_stores_its_dictionaries_and_keeps_sampling_parameters_open(colour_exemplar, tmp_path):
    model = fast_method("sparse").fit(colour_exemplar)
    path = texsyn.save(model, tmp_path / "sparse.npz")
    with np.load(path, allow_pickle=False) as data:
        assert "fitted/s0_dictionary" in data.files
    faster = texsyn.load(path, n_outer=1)
    assert faster.n_outer == 1
    np.testing.assert_array_equal(faster.model_.scales[0].dictionary, model.model_.scales[0].dictionary)
    with pytest.raises(InputError, match="patch_size"):
        texsyn.load(path, patch_size=8)


def test_a_texsyn_0_1_sparse_file_still_loads(colour_exemplar, tmp_path):
    model = fast_method("sparse").fit(colour_exemplar)
    with pytest.warns(DeprecationWarning, match="fitted_state"):
        state = model.fitted_state()
    params = json.loads(str(state["params"]))
    params["random_state"] = params.pop("fit_rng")  # texsyn 0.1's name of the seed
    state["params"] = np.array(json.dumps(params))
    path = tmp_path / "old.npz"
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **state)
    loaded = texsyn.load(path)
    assert loaded.sample((20, 20), rng=1).tobytes() == model.sample((20, 20), rng=1).tobytes()
    with pytest.warns(DeprecationWarning, match="from_fitted_state"):
        again = type(model).from_fitted_state(state, n_outer=1)
    assert again.n_outer == 1 and again.sample((20, 20), rng=1).shape == (20, 20, 3)
    with pytest.raises(InputError, match="patch_size"), pytest.warns(DeprecationWarning):
        type(model).from_fitted_state(state, patch_size=8)


def test_existing_file_is_kept_without_overwrite(saved_random_phase):
    model, path = saved_random_phase
    before = path.read_bytes()
    with pytest.raises(OutputExistsError, match="overwrite"):
        texsyn.save(model, path)
    assert path.read_bytes() == before
    texsyn.save(model, path, overwrite=True)
    assert texsyn.load(path).get_params() == model.get_params()


def test_save_refuses_unfitted_models_and_other_suffixes(tmp_path):
    with pytest.raises(InputError, match="not fitted"):
        texsyn.save(texsyn.make_method("random_phase"), tmp_path / "m.npz")
    model = texsyn.make_method("random_phase").fit(texsyn.data.exemplar("gravel", size=16))
    with pytest.raises(InputError, match="npz"):
        texsyn.save(model, tmp_path / "m.png")
    assert not list(tmp_path.iterdir())


def _rewrite(path, target, **change):
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    header = json.loads(str(arrays["header"]))
    header.update(change)
    arrays["header"] = np.array(json.dumps(header))
    with open(target, "wb") as fh:
        np.savez(fh, **arrays)
    return target


def test_a_newer_format_version_is_refused(saved_random_phase, tmp_path):
    path = _rewrite(saved_random_phase[1], tmp_path / "new.npz", format_version=FORMAT_VERSION + 1)
    with pytest.raises(InputError, match="format version 2.*upgrade texsyn"):
        texsyn.load(path)


def test_an_unknown_method_is_refused(saved_random_phase, tmp_path):
    path = _rewrite(saved_random_phase[1], tmp_path / "unknown.npz", method="deep_dream")
    with pytest.raises(InputError, match="'deep_dream'.*known methods"):
        texsyn.load(path)


def test_a_foreign_format_is_refused(saved_random_phase, tmp_path):
    path = _rewrite(saved_random_phase[1], tmp_path / "other.npz", format="something-else")
    with pytest.raises(InputError, match="not a saved texsyn model"):
        texsyn.load(path)
    plain = tmp_path / "plain.npz"
    with open(plain, "wb") as fh:
        np.savez(fh, image=np.zeros((4, 4)))
    with pytest.raises(InputError, match="no header"):
        texsyn.load(plain)


@pytest.mark.parametrize("keep", [0.0, 0.3, 0.9])
def test_a_truncated_file_is_refused(saved_random_phase, tmp_path, keep):
    data = saved_random_phase[1].read_bytes()
    path = tmp_path / "cut.npz"
    path.write_bytes(data[: int(keep * len(data))])
    with pytest.raises(InputError, match="not a saved texsyn model"):
        texsyn.load(path)


def test_a_missing_file_and_unknown_parameters_are_refused(saved_random_phase, tmp_path):
    with pytest.raises(InputFileNotFoundError):
        texsyn.load(tmp_path / "nothing.npz")
    with pytest.raises(InputError, match="unknown parameter 'no_such_option'"):
        texsyn.load(saved_random_phase[1], no_such_option=1)


def test_texsyn_0_1_names_still_work_with_a_warning(saved_random_phase, tmp_path):
    model, _ = saved_random_phase
    with pytest.warns(DeprecationWarning, match="texsyn.save"):
        from texsyn.io import save_fitted
    with pytest.warns(DeprecationWarning, match="texsyn.load"):
        from texsyn.io import load_fitted
    path = save_fitted(tmp_path / "old_api.npz", model)
    path = save_fitted(tmp_path / "old_api.npz", model)  # texsyn 0.1 replaced files
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = load_fitted(path)
    assert loaded.sample((8, 8), rng=0).tobytes() == model.sample((8, 8), rng=0).tobytes()


def _strip_params(path, target, *names):
    """A copy of a saved model without some parameters: a file written before they existed."""
    with np.load(path, allow_pickle=False) as data:
        header = json.loads(str(data["header"]))
    params = {k: v for k, v in header["params"].items() if k not in names}
    return _rewrite(path, target, params=params)


#: the parameters of every method in texsyn 0.2.0, the first release with model files
PARAMS_0_2_0 = {
    "clg": "patch_size n_neighbors overlap sigma mode seed_patch seam".split(),
    "cwt": "levels window tolerance seed candidates filters refine refine_radius".split(),
    "efros_leung": "window_size tolerance max_error seed_size".split(),
    "grouplets": (
        "flow n_iterations levels grouplet_levels sigma presmooth colour tau viscosity "
        "texture_viscosity speed initial_flow n_projections keep_speed"
    ).split(),
    "heeger_bergen": "n_scales n_orientations n_iterations periodic_component".split(),
    "lg": "patch_size n_neighbors overlap mode seed_patch seam".split(),
    "mslg": "patch_size n_neighbors n_scales mode seed_patch zoom_boundary post post_iterations".split(),
    "patch_wavelet": (
        "min_width max_resolution sigma feature_width embedding_dim lle_neighbors "
        "lle_points exemplar_boundary candidates fit_rng"
    ).split(),
    "portilla_simoncelli": "n_scales n_orientations lags n_iterations colour".split(),
    "quilting": "patch_size overlap tolerance boundary_cut".split(),
    "random_phase": "periodic_component".split(),
    "rclg": "patch_size n_neighbors overlap sigma theta mode seed_patch seam".split(),
    "sparse": (
        "patch_size step n_scales sparsity n_atoms alpha beta n_outer n_inner mode "
        "lowpass_ref final_histogram random_offset ksvd_iterations ksvd_training "
        "tolerance fit_rng"
    ).split(),
    "wei_levoy": "levels window parent_window search leaf_size fit_rng".split(),
}


def test_every_parameter_added_since_0_2_0_has_its_old_value_in_the_table():
    for name, cls in texsyn.METHODS.items():
        added = [k for k in cls.param_specs() if k not in PARAMS_0_2_0.get(name, [])]
        assert sorted(ADDED_PARAMS.get(name, {})) == sorted(added), name
        for key, entry in ADDED_PARAMS.get(name, {}).items():
            if entry.old is not DEFAULT:
                cls.param_specs()[key].check(entry.old, name)  # an allowed value


OLD_FILES = [
    ("lg", {"histogram": "none"}),
    ("clg", {"histogram": "none", "looseness": 0.0}),
    ("rclg", {"histogram": "none", "looseness": 0.0}),
    ("mslg", {"coarse_seam": "average", "histogram": "none"}),
]


@pytest.mark.parametrize("name, old", OLD_FILES, ids=[n for n, _ in OLD_FILES])
def test_a_file_older_than_a_parameter_loads_with_its_old_value_and_one_warning(
    name, old, colour_exemplar, tmp_path
):
    model = fast_method(name).fit(colour_exemplar)
    path = _strip_params(texsyn.save(model, tmp_path / "new.npz"), tmp_path / "old.npz", *old)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loaded = texsyn.load(path)  # texsyn 0.2 loaded the newer defaults without a word
    assert len(caught) == 1, [str(w.message) for w in caught]
    assert caught[0].category is UserWarning
    message = str(caught[0].message)
    assert "old.npz' was written by texsyn" in message
    for key, value in old.items():
        assert getattr(loaded, key) == value
        assert f"{key}={value!r}" in message
    then = texsyn.make_method(name, **{**model.get_params(), **old}).fit(colour_exemplar)
    assert loaded.sample((20, 24), rng=3).tobytes() == then.sample((20, 24), rng=3).tobytes()


def test_a_parameter_given_to_load_or_with_an_unchanged_default_gives_no_warning(colour_exemplar, tmp_path):
    model = fast_method("clg").fit(colour_exemplar)
    path = _strip_params(
        texsyn.save(model, tmp_path / "new.npz"), tmp_path / "old.npz", "histogram", "looseness"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = texsyn.load(path, histogram="match", looseness=0.5)
    assert (loaded.histogram, loaded.looseness) == ("match", 0.5)
    with pytest.warns(UserWarning, match=r"parameter looseness: loaded with looseness=0\.0") as caught:
        assert texsyn.load(path, histogram="match").looseness == 0.0
    assert len(caught) == 1
    ps = texsyn.make_method("portilla_simoncelli", n_scales=2, n_iterations=1).fit(colour_exemplar)
    ps_path = _strip_params(texsyn.save(ps, tmp_path / "ps.npz"), tmp_path / "ps_old.npz", "record_distance")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the old value is the default: nothing to say
        assert texsyn.load(ps_path).record_distance is False


def test_a_missing_parameter_the_table_does_not_know_keeps_its_default_with_a_warning(
    saved_random_phase, tmp_path
):
    path = _strip_params(saved_random_phase[1], tmp_path / "edited.npz", "periodic_component")
    with pytest.warns(UserWarning, match="periodic_component=True .its default"):
        assert texsyn.load(path).periodic_component is True


def test_sparse_random_state_is_a_deprecated_name_of_fit_rng():
    with pytest.warns(DeprecationWarning, match="'random_state'.*'fit_rng'"):
        method = texsyn.make_method("sparse", random_state=7)
    assert method.fit_rng == 7
    with pytest.warns(DeprecationWarning):
        assert texsyn.methods.ConstrainedSparse(random_state=3).fit_rng == 3
    with pytest.raises(InputError, match="give only 'fit_rng'"):
        texsyn.make_method("sparse", random_state=7, fit_rng=7)


# --------------------------------------------------------------------------- hostile files
# Files built by hand (numpy's .npy writer on zip members): each must be refused with one
# InputError line, at once, without allocating what the file declares (docs/persistence.md,
# "Reading a file from someone else").


def _npy(array=None, *, shape=(), descr="<f8", data=b""):
    """An .npy member: a real array, or a header declaring ``shape``/``descr`` and then ``data``."""
    buf = io.BytesIO()
    if array is not None:
        np.lib.format.write_array(buf, np.asarray(array), allow_pickle=False)
    else:
        np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False, "shape": shape})
        buf.write(data)
    return buf.getvalue()


def _header(method="random_phase", **change):
    header = {
        "format": "texsyn-model",
        "format_version": FORMAT_VERSION,
        "texsyn_version": texsyn.__version__,
        "method": method,
        "params": {},
        **change,
    }
    return _npy(np.array(json.dumps(header)))


def _archive(path, members, compression=zipfile.ZIP_DEFLATED):
    with zipfile.ZipFile(path, "w", compression) as zf:
        for name, payload in members.items():
            zf.writestr(name + ".npy", payload)
    return path


def _refused(path, match, error=InputError):
    """Load ``path``: one ``error`` line matching ``match``, fast, with little memory."""
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(error, match=match) as info:
            texsyn.load(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - start < 2.0
    assert peak < 20 * 2**20, f"loading took {peak} bytes"
    message = str(info.value)
    assert "\n" not in message and len(message) < 400, message
    assert isinstance(info.value, InputError) and isinstance(info.value, ValueError)
    return message


_SMALL = np.full((8, 8, 3), 0.5)


@pytest.mark.parametrize("shape", [(10**6, 10**6), (8000, 8000), (10**6, 10**6, 3)])
def test_an_exemplar_declared_over_the_pixel_budget_is_refused_unread(tmp_path, shape):
    path = _archive(tmp_path / "huge.npz", {"header": _header(), "exemplar": _npy(shape=shape)})
    assert path.stat().st_size < 2000
    message = _refused(path, "exemplar.*more than the 40 million allowed; set TEXSYN_MAX_PIXELS=")
    assert "huge.npz" in message


def test_the_exemplar_budgets_of_image_files_and_of_the_method_apply(saved_random_phase, monkeypatch):
    path = saved_random_phase[1]
    monkeypatch.setenv("TEXSYN_MAX_PIXELS", "100")
    assert _refused(path, "more than the 100 allowed; set TEXSYN_MAX_PIXELS=")
    monkeypatch.delenv("TEXSYN_MAX_PIXELS")
    monkeypatch.setenv("TEXSYN_MEMORY_LIMIT", "1M")
    message = _refused(path, "rp.npz.*random_phase.*fitting.*TEXSYN_MEMORY_LIMIT", MemoryLimitError)
    assert "docs/memory.md" in message


def test_learned_arrays_over_the_memory_limit_are_refused_unread(tmp_path, monkeypatch):
    big = np.random.default_rng(0).random((320, 1000))  # 2.5 MiB
    members = {"header": _header("sparse"), "exemplar": _npy(_SMALL), "fitted/s0_dictionary": _npy(big)}
    path = _archive(tmp_path / "learned.npz", members, zipfile.ZIP_STORED)
    monkeypatch.setenv("TEXSYN_MEMORY_LIMIT", "2M")
    assert _refused(path, "loading the arrays of .*learned.npz.*TEXSYN_MEMORY_LIMIT", MemoryLimitError)


def test_arrays_declaring_more_than_the_file_can_hold_are_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("TEXSYN_MEMORY_LIMIT", "64G")  # the size checks, not the memory limit
    bomb = _archive(tmp_path / "bomb.npz", {"header": _header(), "exemplar": _npy(shape=(3000, 3000))})
    assert _refused(
        bomb, r"declares 68.7 MiB of arrays in \d+ bytes, over 1100:1: refused as a decompression bomb"
    )
    cut = _archive(tmp_path / "cut.npz", {"header": _header(), "exemplar": _npy(shape=(100, 100, 3))})
    assert _refused(cut, "array 'exemplar' declares 234.4 KiB but holds 128 bytes: truncated or forged")
    short = _archive(tmp_path / "short.npz", {"header": _header(), "exemplar": _npy(_SMALL)[:-8]})
    assert _refused(short, "array 'exemplar'")


def test_a_compression_numpy_never_writes_is_refused(tmp_path):
    members = {"header": _header(), "exemplar": _npy(_SMALL)}
    path = _archive(tmp_path / "bz.npz", members, zipfile.ZIP_BZIP2)
    assert _refused(path, "compressed in a way numpy never writes")


@pytest.mark.parametrize("member", ["header", "exemplar", "fitted/s0_dictionary"])
def test_python_objects_are_refused_from_the_array_header(tmp_path, member):
    members = {
        "header": _header(),
        "exemplar": _npy(_SMALL),
        member: _npy(shape=(2,), descr="|O", data=b"x" * 16),
    }
    path = _archive(tmp_path / "objects.npz", members)
    assert _refused(path, f"array '{member}' holds Python objects")


@pytest.mark.parametrize(
    "text, match",
    [
        ("[" * 100_000, "header is not a texsyn-model header"),
        ("{" * 100_000, "header is not a texsyn-model header"),
        ('{"format": "texsyn-model", "params": ' + "[" * 100_000, "header is not a texsyn-model header"),
    ],
)
def test_a_deeply_nested_header_is_refused(tmp_path, text, match):
    path = _archive(tmp_path / "nested.npz", {"header": _npy(np.array(text)), "exemplar": _npy(_SMALL)})
    assert _refused(path, match)


def test_a_deeply_nested_texsyn_0_1_header_is_refused(tmp_path):
    members = {
        "format_version": _npy(np.array(1)),
        "method": _npy(np.array("sparse")),
        "params": _npy(np.array("[" * 100_000)),
        "exemplar": _npy(_SMALL),
    }
    assert _refused(_archive(tmp_path / "old.npz", members), "parameters are not a mapping")


def test_a_header_over_a_million_characters_is_refused_unread(tmp_path):
    members = {"header": _npy(shape=(), descr="<U50000000"), "exemplar": _npy(_SMALL)}
    assert _refused(_archive(tmp_path / "long.npz", members), "header is over 1,000,000 characters long")


@pytest.mark.parametrize(
    "content",
    [b"\x89PNG\r\n\x1a\n" + bytes(200), _npy(_SMALL), b"", b"just some text\n"],
    ids=["png", "npy", "empty", "text"],
)
def test_a_file_that_is_not_an_archive_gets_our_own_message(tmp_path, monkeypatch, content):
    monkeypatch.chdir(tmp_path)
    Path("picture.npz").write_bytes(content)
    message = _refused("picture.npz", "not an .npz archive")
    assert message == "'picture.npz' is not a saved texsyn model (not an .npz archive)"
    assert "pickle" not in message


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_pipe_is_refused_without_waiting_for_a_writer(tmp_path):
    path = tmp_path / "pipe.npz"
    os.mkfifo(path)
    assert _refused(path, "not a regular file")
    assert _refused(tmp_path, "is a folder")


def test_every_refusal_is_an_input_error_that_front_doors_map_to_exit_2():
    # texsyn.cli.report_error gives exit status 2 exactly for InputError (docs/errors.md)
    assert issubclass(InputError, ValueError)
    assert issubclass(MemoryLimitError, InputError) and issubclass(InputFileNotFoundError, InputError)


def test_arrays_a_method_never_stores_are_refused_before_they_are_read(tmp_path, monkeypatch):
    monkeypatch.setenv("TEXSYN_MEMORY_LIMIT", "64G")  # the name check, not the memory limit
    junk = _npy(shape=(64 * 2**20,), descr="|u1", data=bytes(64 * 2**20))  # deflates to ~64 KiB
    members = {"header": _header(), "exemplar": _npy(_SMALL), "fitted/junk": junk}
    path = _archive(tmp_path / "junk.npz", members)
    assert "holds no arrays named 'junk'" in _refused(path, "random_phase")
    odd = {"header": _header(), "exemplar": _npy(_SMALL), "fitted/\x1b[31mred\n\rx": _npy(_SMALL)}
    message = _refused(_archive(tmp_path / "odd.npz", odd), "holds no arrays named")
    assert "\x1b" not in message and "\r" not in message


FORGERIES = {
    "atom-size": lambda a: {
        "s0_dictionary": np.zeros((4 * a["s0_dictionary"].shape[0], a["s0_dictionary"].shape[1]))
    },
    "empty-histogram": lambda a: {"s0_sorted": np.zeros((a["s0_sorted"].shape[0], 0))},
    "nan": lambda a: {"s0_dictionary": np.full(a["s0_dictionary"].shape, np.nan)},
    "negative-usage": lambda a: {"s0_usage": -np.ones_like(a["s0_usage"])},
}


@pytest.mark.parametrize("forgery", sorted(FORGERIES))
def test_forged_sparse_arrays_are_refused_at_load_not_at_sample(tmp_path, colour_exemplar, forgery):
    model = fast_method("sparse").fit(colour_exemplar)
    path = texsyn.save(model, tmp_path / "sparse.npz")
    with np.load(path, allow_pickle=False) as stored:
        members = {k: stored[k] for k in stored.files}
    forged = FORGERIES[forgery](model.fitted_arrays())
    members.update({f"fitted/{k}": v for k, v in forged.items()})
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **members)
    with pytest.raises(InputError, match="saved sparse model"):
        texsyn.load(path)
