"""Fitted state is immutable (``docs/architecture.md``, "Fitted state"; issue 17).

``fit`` computes everything ``sample`` needs; ``sample`` never changes it: a deep snapshot of
the fitted object (every attribute, recursively: arrays by their bytes, dataclasses, dicts,
lists, objects' attributes) is the same after sampling, and a model sampled twice gives the
images of two fresh fits.
"""

from __future__ import annotations

import dataclasses
import types

import numpy as np
import pytest

import texsyn
from conftest import fast_method


def snapshot(value, seen=None):
    """A comparable, deep description of ``value``: arrays by dtype, shape and bytes."""
    seen = {} if seen is None else seen
    if value is None or isinstance(value, (bool, int, str, bytes)):
        return value
    if isinstance(value, float):
        return ("float", repr(value))
    if isinstance(value, np.generic):
        return ("scalar", str(value.dtype), value.tobytes())
    if isinstance(
        value, (types.FunctionType, types.BuiltinFunctionType, types.MethodType, type, types.ModuleType)
    ):
        return ("callable", getattr(value, "__qualname__", repr(type(value))))
    key = id(value)
    if key in seen:
        return ("seen", seen[key])
    seen[key] = len(seen)
    if isinstance(value, np.ndarray):
        if value.dtype == object:
            return ("objects", value.shape, [snapshot(v, seen) for v in value.ravel()])
        return ("array", str(value.dtype), value.shape, np.ascontiguousarray(value).tobytes())
    if isinstance(value, np.random.Generator):
        return ("generator", repr(value.bit_generator.state))
    if isinstance(value, dict):
        return (
            "dict",
            [(repr(k), snapshot(v, seen)) for k, v in sorted(value.items(), key=lambda kv: repr(kv[0]))],
        )
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, [snapshot(v, seen) for v in value])
    if isinstance(value, (set, frozenset)):
        return ("set", sorted(repr(v) for v in value))
    out = [type(value).__qualname__]
    if dataclasses.is_dataclass(value):
        out.append([(f.name, snapshot(getattr(value, f.name), seen)) for f in dataclasses.fields(value)])
    if hasattr(value, "__dict__"):
        out.append(snapshot(vars(value), seen))
    for cls in type(value).__mro__:
        for name in getattr(cls, "__slots__", ()):
            if hasattr(value, name):
                out.append((name, snapshot(getattr(value, name), seen)))
    if len(out) == 1:
        out.append(repr(value))  # an opaque object: its representation
    return tuple(out)


def differences(a, b, where="model"):
    """Paths where two snapshots differ (for a readable failure)."""
    if type(a) is not type(b) or (not isinstance(a, (tuple, list)) and a != b):
        return [where]
    if isinstance(a, (tuple, list)):
        if len(a) != len(b):
            return [where]
        out = []
        for i, (x, y) in enumerate(zip(a, b)):
            label = x[0] if isinstance(x, tuple) and len(x) == 2 and isinstance(x[0], str) else i
            out += differences(x, y, f"{where}/{label}")
        return out
    return []


@pytest.mark.parametrize("name", sorted(texsyn.METHODS))
def test_sampling_does_not_change_the_fitted_state(name, colour_exemplar):
    model = fast_method(name).fit(colour_exemplar)
    before = snapshot(model)
    model.sample_with_map((24, 28), rng=1)
    model.sample_with_map((30, 20), rng=2)
    after = snapshot(model)
    assert not differences(before, after), differences(before, after)[:10]


@pytest.mark.parametrize("name", sorted(texsyn.METHODS))
def test_a_model_sampled_twice_gives_the_images_of_two_fresh_fits(name, colour_exemplar):
    shared = fast_method(name).fit(colour_exemplar)
    for seed, shape in ((1, (24, 28)), (2, (30, 20))):
        again = shared.sample_with_map(shape, rng=seed)
        fresh = fast_method(name).fit(colour_exemplar).sample_with_map(shape, rng=seed)
        assert again.image.tobytes() == fresh.image.tobytes(), seed
        if fresh.source_map is None:
            assert again.source_map is None
        else:
            assert again.source_map.tobytes() == fresh.source_map.tobytes(), seed
