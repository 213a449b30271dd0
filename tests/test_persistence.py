"""Saved models (``docs/persistence.md``): one versioned format for every method.

save -> load -> sample gives the bytes of sampling the saved model, for every method; bad
files are refused with one clear :class:`~texsyn.errors.InputError`.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import texsyn
from conftest import fast_method
from texsyn.errors import InputError, InputFileNotFoundError, OutputExistsError
from texsyn.persistence import FORMAT_VERSION


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


def test_sparse_random_state_is_a_deprecated_name_of_fit_rng():
    with pytest.warns(DeprecationWarning, match="'random_state'.*'fit_rng'"):
        method = texsyn.make_method("sparse", random_state=7)
    assert method.fit_rng == 7
    with pytest.warns(DeprecationWarning):
        assert texsyn.methods.ConstrainedSparse(random_state=3).fit_rng == 3
    with pytest.raises(InputError, match="give only 'fit_rng'"):
        texsyn.make_method("sparse", random_state=7, fit_rng=7)
