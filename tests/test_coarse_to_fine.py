"""The coarse-to-fine driver and the methods that walk it: cwt and Wei-Levoy (issue 17)."""

import pickle
import warnings

import numpy as np
import pytest

import texsyn
from texsyn.drivers.coarse_to_fine import coarse_to_fine
from texsyn.ops.progress import Reporter
from texsyn.transforms.dtcwt import DTCWT, DTCWTPyramid


def test_the_walk_goes_from_the_coarsest_level_to_the_finest():
    visited = []

    def step(level, coarser):
        visited.append((level, coarser))
        return f"L{level}"

    states = coarse_to_fine(step, 3, start="seed")
    assert visited == [(2, "seed"), (1, "L2"), (0, "L1")]
    assert states == ["L0", "L1", "L2"]  # 0-based, the finest first


def test_the_walk_reports_levels_done_with_a_preview():
    seen = []
    coarse_to_fine(
        lambda level, coarser: level, 3, reporter=Reporter(seen.append, "levels", 3), preview=lambda s: -s
    )
    assert [(p.stage, p.done, p.total, p.image) for p in seen] == [
        ("levels", 1, 3, -2),
        ("levels", 2, 3, -1),
        ("levels", 3, 3, 0),
    ]
    with pytest.raises(ValueError, match="at least 1"):
        coarse_to_fine(lambda level, coarser: level, 0)


def test_a_listener_without_images_gets_no_preview_and_none_is_computed():
    class Counts(list):
        wants_images = False

        def __call__(self, record):
            self.append(record)

    seen, previews = Counts(), []
    reporter = Reporter(seen.append, "levels", 2)
    assert reporter.active and reporter.wants_images
    reporter = Reporter(seen, "levels", 2)
    assert reporter.active and not reporter.wants_images
    coarse_to_fine(lambda level, coarser: level, 2, reporter=reporter, preview=previews.append)
    assert previews == [] and [p.image for p in seen] == [None, None]
    assert not Reporter(Reporter(seen).relabel("outer"), "inner").wants_images  # relabel keeps it


def test_dtcwt_levels_are_zero_based_the_finest_first():
    x = np.random.default_rng(0).random((32, 16))
    pyr = DTCWT(3).forward(x)
    assert isinstance(pyr, DTCWTPyramid) and pyr.levels == 3
    assert pyr[0, 2].shape == (16, 8) and pyr[2, 5].shape == (4, 2)
    np.testing.assert_array_equal(pyr[1, 3], pyr.highpasses[1][..., 3])
    assert pyr.keys()[0] == (0, 0) and pyr.keys()[-1] == "lowpass" and len(pyr.items()) == 19


def test_the_old_dtcwt_module_is_a_deprecated_alias():
    import importlib
    import sys

    for name in ("texsyn.ops.dtcwt", "texsyn.ops.dtcwt_filters"):
        sys.modules.pop(name, None)
        with pytest.warns(DeprecationWarning, match="texsyn.transforms"):
            module = importlib.import_module(name)
        if name.endswith("dtcwt"):
            assert module.DTCWT is DTCWT and module.DTCWTPyramid is DTCWTPyramid


@pytest.mark.parametrize(
    "name, params",
    [
        ("cwt", {"levels": 2}),
        ("cwt", {"levels": 2, "refine": True, "seed": "random"}),
        ("wei_levoy", {"levels": 2, "window": 5}),
        ("wei_levoy", {"levels": 2, "window": 5, "search": "tsvq", "leaf_size": 8}),
    ],
)
def test_sampling_never_changes_the_fitted_model(name, params):
    ex = texsyn.data.exemplar("brick", size=32)
    model = texsyn.make_method(name, **params).fit(ex)
    fitted = pickle.dumps({k: v for k, v in vars(model).items() if k.endswith("_")})
    first = model.sample_with_map((24, 28), rng=1)
    second = model.sample_with_map((24, 28), rng=2)
    assert pickle.dumps({k: v for k, v in vars(model).items() if k.endswith("_")}) == fitted
    fresh = [texsyn.make_method(name, **params).fit(ex).sample_with_map((24, 28), rng=r) for r in (1, 2)]
    for a, b in zip((first, second), fresh):
        np.testing.assert_array_equal(a.image, b.image)
        np.testing.assert_array_equal(a.source_map, b.source_map)


@pytest.mark.parametrize(
    "name, old, new, value",
    [("cwt", "epsilon", "tolerance", 0.5), ("wei_levoy", "random_state", "fit_rng", 7)],
)
def test_renamed_parameters_keep_their_old_names(name, old, new, value):
    ex = texsyn.data.exemplar("gravel", size=32)
    small = {"levels": 2} if name == "cwt" else {"levels": 2, "window": 5, "search": "tsvq", "leaf_size": 8}
    with pytest.warns(DeprecationWarning, match=f"{old!r}.*deprecated.*{new!r}"):
        legacy = texsyn.make_method(name, **small, **{old: value})
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        current = texsyn.make_method(name, **small, **{new: value})
    assert legacy.get_params() == current.get_params() and getattr(current, new) == value
    np.testing.assert_array_equal(
        legacy.fit(ex).sample((20, 20), rng=0), current.fit(ex).sample((20, 20), rng=0)
    )
