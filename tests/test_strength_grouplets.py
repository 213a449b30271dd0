"""What makes Peyré's grouplet synthesis (2008) what it is (issue 16): static syntheses with
the exemplar's statistics, and fluid-driven frames that move with their flow.

Bounds come from measurements (real output / shuffled pixels / blurred, sigma 1.5, as
``tests/sabotage.py`` makes them; ``band_log2_ratios`` with 3 scales: [high-pass, scale 0,
scale 1, scale 2]): static syntheses of a 48x48 crop of brick, 48x48, seeds 0-5; animations
of a 48x48 crop of gravel, 32x32 frames, seeds 0-3. The measured ranges are in the comments.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import texsyn
from strength_utils import autocorrelation_gap, band_log2_ratios
from texsyn.metrics import sharpness_ratio
from texsyn.ops.flow import builtin_flow
from texsyn.ops.fluid import advect

BRICK = texsyn.data.exemplar("brick", size=48)
GRAVEL = texsyn.data.exemplar("gravel", size=48)
SEEDS = (0, 1, 2)
#: static synthesis: few iterations, still converged enough for the statistics below
STATIC = dict(colour="grey", n_iterations=8, levels=3, grouplet_levels=3)
#: the fastest dynamic run: a swirling flow (smoothed noise) fast enough to see the texture move
DYNAMIC = dict(colour="grey", n_iterations=3, levels=2, grouplet_levels=3, initial_flow="noise", speed=2.0)
FRAME = (32, 32)


@functools.cache
def static_method():
    return texsyn.make_method("grouplets", **STATIC).fit(BRICK)


@functools.cache
def static_outputs(kind: str) -> tuple:
    method = static_method()
    if kind == "sample":
        return tuple(method.sample((48, 48), rng=seed) for seed in SEEDS)
    flow = builtin_flow("vortex", (48, 48))
    return tuple(method.synthesize_along(flow, rng=seed) for seed in SEEDS)


@functools.cache
def dynamic_method():
    return texsyn.make_method("grouplets", **DYNAMIC).fit(GRAVEL)


@functools.cache
def frames(seed: int, n_frames: int = 12) -> tuple:
    return tuple(dynamic_method().animate(n_frames, FRAME, rng=seed))


# ---------------------------------------------------------------------- static synthesis
@pytest.mark.method("grouplets")
@pytest.mark.parametrize("kind", ["sample", "along a vortex"])
def test_grouplets_synthesis_has_the_exemplars_band_energies(kind):
    # log2 energy ratios, seeds 0-5, learned flow and vortex (real / shuffled / blurred):
    #   high-pass  0.72 .. 1.23 / 6.50 .. 6.59 / -6.17 .. -3.97
    #   scale 0    0.08 .. 0.74 / 2.61 .. 2.79 / -4.20 .. -3.48
    #   scale 1   -0.04 .. 0.20 / -2.21 .. -1.89 / -1.89 .. -1.47
    for out in static_outputs(kind.split()[0]):
        ratios = band_log2_ratios(out, BRICK, 3)
        assert abs(ratios[0]) <= 2.5, ratios
        assert abs(ratios[1]) <= 1.5, ratios
        assert np.all(np.abs(ratios[2:]) <= 1.0), ratios


@pytest.mark.method("grouplets")
@pytest.mark.parametrize("kind", ["sample", "along a vortex"])
def test_grouplets_synthesis_is_as_sharp_and_as_correlated_as_the_exemplar(kind):
    for out in static_outputs(kind.split()[0]):
        # mean gradient over the exemplar's: real 1.00 .. 1.08, shuffled 4.16 .. 4.30,
        # blurred 0.63 .. 0.67
        assert 0.8 <= sharpness_ratio(out, BRICK) <= 1.5
        # autocorrelation gap at lags up to 2 px: real 0.06 .. 0.22, shuffled 0.93 .. 0.97
        # (blurred 0.21 .. 0.34: caught by the two statistics above)
        assert autocorrelation_gap(out, BRICK) <= 0.5


# ---------------------------------------------------------------------- dynamic synthesis
@pytest.mark.method("animate")
@pytest.mark.parametrize("seed", [0, 1])
def test_each_frame_is_the_previous_one_advected_by_its_flow(seed):
    """Paper Table 2: frame t+1 is frame t warped by the flow (then diffused and projected)."""
    run = frames(seed)
    tau = dynamic_method().tau
    images = [f.image.astype(np.float64) for f in run]
    advected = [np.abs(images[t + 1] - advect(images[t], run[t].flow, tau)).mean() for t in range(1, 11)]
    still = [np.abs(images[t + 1] - images[t]).mean() for t in range(1, 11)]
    # a frame and an independent synthesis along its flow differ by 0.15 .. 0.21 (mean absolute)
    independent = [
        np.abs(dynamic_method().synthesize_along(run[t].flow, rng=100 + t) - images[t]).mean() for t in (1, 6)
    ]
    # mean |F_t+1 - advect(F_t)|, seeds 0-3: real 0.008 .. 0.010, at most 0.015 per step
    # (0.07 .. 0.09 of the independent difference); shuffled 0.14 .. 0.15; frozen frames 0.05;
    # independent frames 0.17 .. 0.21
    assert max(advected) <= 0.25 * min(independent), (advected, independent)
    # the warp explains the change: mean ratio, real 0.17 .. 0.22 (frozen: no change at all)
    assert np.mean(advected) <= 0.4 * np.mean(still), (advected, still)


@pytest.mark.method("animate")
def test_the_texture_moves_from_frame_to_frame():
    run = frames(0)
    steps = [np.abs(run[t + 1].image.astype(np.float64) - run[t].image).mean() for t in range(len(run) - 1)]
    # mean absolute change per frame, seeds 0-3: real 0.045 .. 0.052 (float32 noise is ~1e-8)
    assert min(steps) >= 0.01, steps
    for frame in run:
        assert np.mean(np.sum(frame.flow**2, axis=-1)) > 1.0  # the flow keeps its speed (RMS 2)


@pytest.mark.method("animate")
@pytest.mark.parametrize("index", [0, 1])
def test_first_frames_have_the_exemplars_statistics(index):
    # frames 0 and 1 against gravel, seeds 0-3 (real / shuffled / blurred):
    #   high-pass  0.56 .. 1.54 / 4.65 .. 4.76 / -7.33 .. -5.60
    #   scale 0   -0.88 .. -0.29 / 1.59 .. 1.70 / -5.62 .. -5.24
    #   sharpness  1.14 .. 1.31 / 3.39 .. 3.47 / 0.51 .. 0.54
    for seed in (0, 1):
        image = frames(seed)[index].image
        ratios = band_log2_ratios(image, GRAVEL, 3)
        assert abs(ratios[0]) <= 2.5, ratios
        assert abs(ratios[1]) <= 1.25, ratios
        assert 0.75 <= sharpness_ratio(image, GRAVEL) <= 1.6


@pytest.mark.method("animate")
@pytest.mark.xfail(
    strict=True,
    reason="issue 18: the finest scale fades as the frames are advected and diffused: frame 299 "
    "has 2.7 to 4.4 log2 less high-pass energy than frame 1 for seeds 1-3 (1.5 for seed 0)",
)
def test_frame_300_keeps_the_statistics_of_frame_1_at_every_scale():
    """A fluid texture stays alive: 300 frames on, every scale keeps its energy."""
    run = list(dynamic_method().animate(300, FRAME, rng=3))
    first, last = run[1].image, run[-1].image
    # measured (frame 299 over frame 1, log2, seed 3): high-pass -4.44, scale 0 +0.50,
    # scale 1 -0.05, scale 2 -0.01; a blurred frame has -5.6 .. -8.0 at the high-pass
    ratios = band_log2_ratios(last, first, 3)
    assert np.all(np.abs(ratios) <= 1.5), ratios
    assert np.all(np.abs(band_log2_ratios(last, GRAVEL, 3)[:2]) <= 1.5)
    assert autocorrelation_gap(last, first) <= 0.2
