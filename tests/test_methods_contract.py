"""The contract every registered method keeps (DESIGN.md, tests layer 2)."""

import copy

import numpy as np
import pytest

import texsyn
from conftest import FAST_PARAMS, fast_method
from texsyn._validation import OneOf


def fitted(name, exemplar):
    return fast_method(name).fit(exemplar)


@pytest.mark.parametrize("shape", [(37, 29), (16, 50), (9, 7)])
def test_output_shape_dtype_range_and_rank(method_name, grey_exemplar, shape):
    out = fitted(method_name, grey_exemplar).sample(shape, rng=0)
    assert out.shape == shape
    assert out.dtype == np.float32
    assert out.min() >= 0.0 and out.max() <= 1.0
    assert np.all(np.isfinite(out))


def test_default_shape_is_twice_the_exemplar(method_name, grey_exemplar):
    out = fitted(method_name, grey_exemplar).sample(rng=1)
    assert out.shape == (80, 80)


def test_colour_stays_colour(method_name, colour_exemplar):
    out = fitted(method_name, colour_exemplar).sample((30, 34), rng=0)
    assert out.shape == (30, 34, 3)
    # the channels are not copies of each other
    assert not np.allclose(out[..., 0], out[..., 1])
    assert not np.allclose(out[..., 1], out[..., 2])


def test_same_rng_same_texture_other_rng_other_texture(method_name, colour_exemplar):
    method = fitted(method_name, colour_exemplar)
    a = method.sample((32, 32), rng=7)
    b = method.sample((32, 32), rng=7)
    c = method.sample((32, 32), rng=8)
    d = method.sample((32, 32), rng=np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, d)
    assert not np.array_equal(a, c)


def test_sample_does_not_change_the_fitted_state(method_name, grey_exemplar):
    method = fitted(method_name, grey_exemplar)
    before = copy.deepcopy({k: v for k, v in vars(method).items() if k.endswith("_")})
    method.sample((20, 20), rng=0)
    after = {k: v for k, v in vars(method).items() if k.endswith("_")}
    assert before.keys() == after.keys()
    for key, value in before.items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, after[key])


def test_synthesize_equals_fit_then_sample(method_name, grey_exemplar):
    params = FAST_PARAMS[method_name]
    a = texsyn.synthesize(grey_exemplar, method_name, (24, 24), rng=3, **params)
    b = fitted(method_name, grey_exemplar).sample((24, 24), rng=3)
    np.testing.assert_array_equal(a, b)


def test_source_map_names_exemplar_pixels(method_name, colour_exemplar):
    method = fitted(method_name, colour_exemplar)
    result = method.sample_with_map((33, 27), rng=2)
    if not type(method).has_source_map:
        assert result.source_map is None
        return
    src = result.source_map
    assert src.shape == (33, 27, 2)
    assert src[..., 0].min() >= 0 and src[..., 0].max() < colour_exemplar.shape[0]
    assert src[..., 1].min() >= 0 and src[..., 1].max() < colour_exemplar.shape[1]
    copied = method.source_image[src[..., 0], src[..., 1]]
    if type(method).source_map_exact:
        np.testing.assert_array_equal(result.image, copied.astype(np.float32))
    else:  # coefficients were copied, pixels re-synthesised: close to the named pixels
        assert np.mean(np.abs(result.image - copied)) < 0.25 * np.mean(
            np.abs(colour_exemplar - colour_exemplar.mean())
        )


def test_every_parameter_has_a_default_and_a_description(method_name):
    cls = texsyn.METHODS[method_name]
    specs = cls.param_specs()
    assert set(specs) == set(cls().get_params())
    for spec in specs.values():
        assert spec.description, f"{method_name}.{spec.name} has no docstring entry"
        spec.check(spec.default, method_name)  # the default itself is allowed


def test_out_of_range_parameter_is_rejected(method_name, grey_exemplar):
    specs = texsyn.METHODS[method_name].param_specs()
    numeric = [s for s in specs.values() if s.type in (int, float) and s.allowed is not None]
    for spec in numeric:
        if isinstance(spec.allowed, OneOf):
            bad = max(spec.allowed.values) + 1
        else:
            bad = spec.allowed.low - 1 if spec.allowed.low is not None else spec.allowed.high + 1
        with pytest.raises(ValueError, match=spec.name):
            texsyn.make_method(method_name, **{spec.name: bad}).fit(grey_exemplar)
    with pytest.raises(ValueError, match="unknown parameter 'no_such_option'"):
        texsyn.make_method(method_name, no_such_option=1)


@pytest.mark.parametrize(
    "bad, error, match",
    [
        (np.full((20, 20), np.nan), ValueError, "NaN"),
        (np.zeros((1, 1)), ValueError, "at least 2x2"),
        (np.zeros((0, 5)), ValueError, "at least 2x2"),
        (np.full((20, 20), 2.0), ValueError, r"\[0, 1\]"),
        (np.zeros((20, 20, 5)), ValueError, "shape"),
        ("exemplar.png", TypeError, "path"),
    ],
)
def test_bad_exemplars_are_rejected(method_name, bad, error, match):
    model = fast_method(method_name)
    if isinstance(bad, np.ndarray) and bad.ndim == 3 and bad.shape[2] <= model.max_channels:
        # a method that synthesises channels jointly takes 5 (docs/materials.md): one too many
        bad = np.zeros((20, 20, model.max_channels + 1))
    with pytest.raises(error, match=match):
        model.fit(bad)


def test_exemplar_smaller_than_the_window_is_rejected():
    for name, params in [
        ("quilting", {"patch_size": 32}),
        ("efros_leung", {"window_size": 11}),
        ("heeger_bergen", {}),
    ]:
        with pytest.raises(ValueError, match="too small"):
            texsyn.make_method(name, **params).fit(np.zeros((10, 10)))


def test_bad_shapes_and_rngs_are_rejected(grey_exemplar):
    method = fitted("random_phase", grey_exemplar)
    with pytest.raises(ValueError, match="at least 1 pixel"):
        method.sample((0, 10))
    with pytest.raises(TypeError):
        method.sample((10.5, 10))
    with pytest.raises(ValueError, match="memory"):
        method.sample((10**6, 10**6))
    with pytest.raises(TypeError, match="RandomState"):
        method.sample((8, 8), rng=np.random.RandomState(0))
    with pytest.raises(RuntimeError, match="fitted"):
        texsyn.make_method("quilting").sample((8, 8))


def test_unknown_method_is_rejected(grey_exemplar):
    with pytest.raises(ValueError, match="unknown method 'nope'; choose one of"):
        texsyn.synthesize(grey_exemplar, "nope")
