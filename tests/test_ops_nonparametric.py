import numpy as np

from texsyn.drivers.raster import grow_pixels
from texsyn.ops.nonparametric import NonParametricSampler, schedule_batches
from texsyn.ops.progress import Reporter


def test_batched_growth_equals_one_pixel_at_a_time(colour_exemplar):
    ex = colour_exemplar[:24, :24]
    sampler = NonParametricSampler(ex, 5)
    batched = grow_pixels(sampler, (21, 26), rng=np.random.default_rng(3))
    sequential = grow_pixels(sampler, (21, 26), rng=np.random.default_rng(3), max_batch=1)
    np.testing.assert_array_equal(batched[1], sequential[1])
    np.testing.assert_array_equal(batched[0], sequential[0])


def test_schedule_never_batches_interacting_pixels():
    rng = np.random.default_rng(0)
    rows = rng.integers(0, 30, 200)
    cols = rng.integers(0, 30, 200)
    radius = 2
    batch_of, n_batches = schedule_batches(rows, cols, radius, 30, 30, 1000)
    assert batch_of.min() == 0 and batch_of.max() == n_batches - 1
    for i in range(200):
        for j in range(i + 1, 200):
            near = abs(rows[i] - rows[j]) <= radius and abs(cols[i] - cols[j]) <= radius
            if near:
                # an earlier pixel of the list is processed in an earlier batch
                assert batch_of[i] < batch_of[j]


def test_growth_fills_every_pixel_with_an_exemplar_value(grey_exemplar):
    values, source = grow_pixels(
        NonParametricSampler(grey_exemplar, 7), (30, 20), rng=np.random.default_rng(1)
    )
    assert source.min() >= 0
    np.testing.assert_array_equal(values[..., 0], grey_exemplar[source[..., 0], source[..., 1]])


def test_growth_works_on_any_channel_stack():
    rng = np.random.default_rng(2)
    stack = rng.random((16, 16, 12))
    values, source = grow_pixels(NonParametricSampler(stack, 3), (10, 10), rng=np.random.default_rng(0))
    assert values.shape == (10, 10, 12)
    np.testing.assert_array_equal(values, stack[source[..., 0], source[..., 1]])


def test_max_error_threshold_grows_until_pixels_are_accepted(grey_exemplar):
    counts = []
    values, source = grow_pixels(
        NonParametricSampler(grey_exemplar, 5),
        (12, 12),
        max_error=1e-9,
        rng=np.random.default_rng(0),
        reporter=Reporter(lambda record: counts.append(record.done), "pixels"),
    )
    # some passes accepted nothing (the threshold then grew; measured: 150 of 176 passes)
    assert np.any(np.diff(counts) == 0)
    assert counts[-1] == 144 and source.min() >= 0
    np.testing.assert_array_equal(values[..., 0], grey_exemplar[source[..., 0], source[..., 1]])
