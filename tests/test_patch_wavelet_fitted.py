"""The fitted patch-valued wavelet model is built once and never changed (issue 17).

``fit`` builds the nearest-patch indexes of every window width and the LLE embeddings of the
levels that draw random details; ``sample`` and ``modify`` only read them, so a fitted model
can be shared between threads or pickled for batch workers.
"""

from __future__ import annotations

import importlib
import pickle
import sys
import threading

import numpy as np
import pytest

import texsyn
from texsyn.models.patch_wavelet import ExemplarWindows, PatchWaveletTransform
from texsyn.transforms.patch_wavelet import PatchLifting

BRICK = texsyn.data.exemplar("brick", size=40)
GRAVEL = texsyn.data.exemplar("gravel", size=32)


def fitted_state(model) -> bytes:
    return pickle.dumps({k: v for k, v in vars(model).items() if k.endswith("_")})


@pytest.mark.parametrize("sigma", [(0.0,), (0.2,), (0.0, 0.3)])
def test_sample_and_modify_never_change_the_fitted_model(sigma):
    model = texsyn.make_method("patch_wavelet", sigma=sigma).fit(BRICK)
    before = fitted_state(model)
    first = model.sample_with_map((64, 48), rng=1)
    model.sample_with_map((128, 128), rng=2)
    model.modify(GRAVEL, [0.0, 0.5], equalize=False)
    model.modify(GRAVEL, 0.3)
    assert fitted_state(model) == before
    fresh = texsyn.make_method("patch_wavelet", sigma=sigma).fit(BRICK).sample_with_map((64, 48), rng=1)
    np.testing.assert_array_equal(first.image, fresh.image)
    np.testing.assert_array_equal(first.source_map, fresh.source_map)


def test_fit_builds_every_embedding_sampling_uses(monkeypatch):
    pure = texsyn.make_method("patch_wavelet").fit(BRICK).transform_
    assert set(pure.indexes) == set(pure.widths()) and not pure.embeddings
    model = texsyn.make_method("patch_wavelet", sigma=(0.0, 0.2, 0.0, 0.1)).fit(BRICK)
    assert set(model.transform_.embeddings) == {model.transform_.width(2), model.transform_.width(4)}

    def refuse(self, width):
        raise AssertionError(f"sample built the embedding of width {width}")

    monkeypatch.setattr(PatchWaveletTransform, "_build_embedding", refuse)
    monkeypatch.setattr(PatchWaveletTransform, "_build_index", refuse)
    model.sample((256, 256), rng=0)  # every level up to 7: all widths the exemplar allows


def test_the_fitted_transform_refuses_changes():
    transform = texsyn.make_method("patch_wavelet", sigma=0.1).fit(BRICK).transform_
    with pytest.raises(AttributeError, match="immutable"):
        transform.min_width = 2
    with pytest.raises(AttributeError, match="immutable"):
        transform.windows.boundary = "periodic"
    with pytest.raises(TypeError, match="immutable"):
        transform.indexes[2] = None
    with pytest.raises(TypeError, match="immutable"):
        transform.embeddings.clear()
    with pytest.raises(ValueError, match="read-only"):
        transform.windows.image[0, 0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        transform.embedding(8).coordinates[0, 0] = 1.0
    assert isinstance(transform, PatchLifting)


def test_prepare_returns_a_new_transform_and_leaves_the_old_one_alone():
    transform = PatchWaveletTransform(BRICK, exemplar_boundary="symmetric")
    prepared = transform.prepare()
    assert not transform.embeddings and set(prepared.embeddings) == set(transform.widths())
    assert prepared.indexes[8] is transform.indexes[8]  # what was built is shared


def test_windows_keep_only_the_block_means_they_were_asked_for():
    image = np.random.default_rng(0).random((24, 20, 1))
    lazy = ExemplarWindows(image, "periodic", max_resolution=4)
    eager = ExemplarWindows(image, "periodic", max_resolution=4, widths=(8, 16))
    assert not lazy.means and set(eager.means) == {2, 4}
    rows, cols = np.array([0, 7, 23]), np.array([3, 19, 5])
    np.testing.assert_array_equal(lazy.descriptors(rows, cols, 16), eager.descriptors(rows, cols, 16))
    assert not lazy.means


def test_threads_share_one_fitted_model():
    model = texsyn.make_method("patch_wavelet", sigma=(0.0, 0.2)).fit(BRICK)
    expected = [model.sample((64, 64), rng=seed) for seed in range(4)]
    got = [None] * 4

    def work(seed):
        got[seed] = model.sample((64, 64), rng=seed)

    threads = [threading.Thread(target=work, args=(seed,)) for seed in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for a, b in zip(expected, got):
        np.testing.assert_array_equal(a, b)


def test_a_pickled_model_samples_the_same_texture():
    model = texsyn.make_method("patch_wavelet", sigma=0.1).fit(BRICK)
    copy = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(copy.sample((32, 32), rng=5), model.sample((32, 32), rng=5))


def test_random_state_is_a_deprecated_name_of_fit_rng():
    with pytest.warns(DeprecationWarning, match="'random_state'.*'fit_rng'"):
        method = texsyn.make_method("patch_wavelet", random_state=3)
    assert method.fit_rng == 3
    with pytest.raises(ValueError, match="give only 'fit_rng'"):
        texsyn.make_method("patch_wavelet", random_state=3, fit_rng=3)
    with pytest.warns(DeprecationWarning, match="use rng"):
        transform = PatchWaveletTransform(BRICK[:16, :16], random_state=4)
    assert transform.rng == 4


def test_the_old_module_is_a_deprecated_alias():
    sys.modules.pop("texsyn.ops.patch_wavelet", None)
    with pytest.warns(DeprecationWarning, match="texsyn.models.patch_wavelet"):
        module = importlib.import_module("texsyn.ops.patch_wavelet")
    assert module.PatchWaveletTransform is PatchWaveletTransform
    assert module.ExemplarWindows is ExemplarWindows
