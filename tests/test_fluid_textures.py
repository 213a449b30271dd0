"""Fluid textures that stay alive (issue 18; Peyré 2008, section 4, Table 2).

The acceptance of issue 18 on a small video: 300 frames of 64x64 from a 48x48 crop of the
built-in grass, grey, at default settings. Frame-to-frame coherence is also checked on a
calm video: a 64x64 frame cannot hold the default eddies of a 256x256 video at the default
speed (its layers live 8 frames instead of 31, so the cross-fades are quick), so the calm
video keeps their strain rate instead (``2 pi speed / flow_scale``, about 0.05 per frame:
eddies of 64 pixels at half a pixel per frame); ``benchmarks/fluid_textures.md`` measures
the default 256x256 case. Bounds come from measurements (seeds 0-2, quoted in the
comments); ``tests/sabotage.py`` replaces the frames by shuffled pixels, blurred frames,
frozen frames or independent syntheses to prove each test can fail.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import texsyn
from texsyn.drivers.fluid import FlowDynamics, flow_sequence, looped_flow_sequence, texture_frames
from texsyn.errors import InputError
from texsyn.metrics import laplacian_band_energies
from texsyn.ops.flow import periodic_tiling, structure_tensor_orientation
from texsyn.ops.fluid import (
    advect,
    advect_displacement,
    divergence,
    prefilter,
    rms_speed,
    sample_displaced,
    spectral_velocity,
    vortex_velocity,
)
from texsyn.transforms.grouplet_frame import GroupletTightFrame

GRASS = texsyn.data.exemplar("grass", size=48)
FRAME = (64, 64)
N_FRAMES = 300
#: the strain rate of a default 256x256 video (eddies of 128 pixels at 1 pixel per frame)
VIDEO = (("flow_scale", 64.0), ("speed", 0.5))


@functools.cache
def method(**params):
    return texsyn.make_method("grouplets", colour="grey", **params).fit(GRASS)


def video_method():
    return method(**dict(VIDEO))


@functools.cache
def video(seed: int, n_frames: int = N_FRAMES, loop: int = 0) -> tuple:
    """The calm video (the strain rate of a default 256x256 one)."""
    return tuple(video_method().animate(n_frames, FRAME, rng=seed, loop=loop))


@functools.cache
def default_video(seed: int) -> tuple:
    return tuple(method().animate(N_FRAMES, FRAME, rng=seed))


@functools.cache
def default_flows(seed: int, shape: tuple[int, int] = FRAME) -> tuple:
    """The flow of an animation at default settings (it does not depend on the texture)."""
    m = method()
    rng = np.random.default_rng(seed)
    return tuple(flow_sequence(m.initial_velocity(shape, rng), N_FRAMES, m.dynamics(shape), rng))


def mad(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


def unit(field: np.ndarray) -> np.ndarray:
    return field / np.maximum(np.linalg.norm(field, axis=-1, keepdims=True), 1e-12)


def fine_coherence(image: np.ndarray) -> float:
    """Mean coherence of the structure tensor at a fine scale (1.5 pixels): how stripy."""
    return float(structure_tensor_orientation(image, sigma=1.5, presmooth=0.5)[1].mean())


def detail_ratios(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Energy ratios of the Laplacian detail bands (finest first) of the method's own frame."""
    return (laplacian_band_energies(image, 3) / laplacian_band_energies(reference, 3))[:-1]


# ---------------------------------------------------------------------- acceptance
@pytest.mark.method("animate")
@pytest.mark.parametrize("video_of", [default_video, video], ids=["default", "calm"])
def test_frame_300_keeps_every_band_energy_of_frame_1_and_of_the_exemplar(video_of):
    run = video_of(0)
    first, last = run[0].image, run[-1].image
    # detail bands (finest first), seeds 0-2, default / calm: frame 300 / frame 1
    # 0.95 .. 1.07 / 0.92 .. 1.04, frame 300 / exemplar 0.91 .. 1.01 / 0.92 .. 1.02,
    # frame 1 / exemplar 0.94 .. 1.01
    assert np.all(np.abs(detail_ratios(last, first) - 1) <= 0.10), detail_ratios(last, first)
    assert np.all(np.abs(detail_ratios(last, GRASS) - 1) <= 0.10), detail_ratios(last, GRASS)
    assert np.all(np.abs(detail_ratios(first, GRASS) - 1) <= 0.10), detail_ratios(first, GRASS)
    # the low-pass residual (default 0.95 .. 1.02 of frame 1's, calm 0.95 .. 1.17) has few
    # independent samples at 64x64, so it wanders from frame to frame: 25 %
    low = laplacian_band_energies(last, 3)[-1] / laplacian_band_energies(first, 3)[-1]
    assert abs(low - 1) <= 0.25, low


@pytest.mark.method("animate")
def test_the_material_does_not_turn_into_smooth_stripes():
    """Band energies alone miss it: the paper's literal loop keeps them but draws stripes.

    The fine-scale coherence (structure tensor at 1.5 pixels) of the grass crop is 0.50;
    frames of the default video, every 10th of 300, seeds 0-2: 0.45 .. 0.52. The paper's
    literal loop (advection='paper') reaches 0.66 .. 0.72 from frame 100 on (smooth, locally
    straight stripes; ``tests/sabotage.py`` "stripes").
    """
    reference = fine_coherence(GRASS)
    for frame in default_video(0)[::10]:
        assert abs(fine_coherence(frame.image) - reference) <= 0.08, (
            frame.index,
            fine_coherence(frame.image),
        )


@pytest.mark.method("animate")
def test_frames_follow_their_flow_and_keep_moving():
    run = video(0)
    m = video_method()
    # an independent synthesis along the same flow differs by `independent` on average
    independent = np.mean(
        [mad(run[t].image, m.synthesize_along(run[t].flow, rng=5000 + t)) for t in (100, 200, 299)]
    )
    for t in range(1, N_FRAMES):  # every step: a hard cut anywhere would stand out
        image, before = run[t].image, run[t - 1].image
        warped = advect(before, run[t - 1].flow, m.tau, order=3)
        # warped / independent difference, seeds 0-2, all frames: 0.12 .. 0.23
        assert mad(image, warped) <= 0.3 * independent, (t, mad(image, warped) / independent)
        # the warp explains the change: 0.6 .. 0.82 of the plain difference at half a pixel
        # per frame (frozen frames do not change at all)
        assert mad(image, warped) <= 0.9 * mad(image, before), t
    displacement = np.mean([np.mean(np.linalg.norm(m.tau * f.flow, axis=-1)) for f in run])
    assert displacement > 0.4, displacement  # 0.46 .. 0.47 at 0.5 pixel per frame (RMS)
    # the texture's orientation follows the current flow: mean |cos| between the frame's
    # structure-tensor directions and the flow, every 10th frame, seeds 0-2: 0.73 .. 0.93
    # (0.86 .. 0.88 on average); unrelated directions give 2 / pi = 0.64
    cosines = [
        np.mean(np.abs(np.sum(structure_tensor_orientation(f.image)[0] * unit(f.flow), axis=-1)))
        for f in run[::10]
    ]
    assert np.mean(cosines) > 0.8 and min(cosines) > 0.68, cosines


def test_a_frames_flow_is_its_own():
    frames = method(n_iterations=2).animate(3, (32, 32), rng=0)
    first = next(frames)
    kept = first.flow.copy()
    first.flow[...] = 0.0  # a caller may change what it was given
    second = next(frames)
    assert not np.shares_memory(first.flow, second.flow)
    again = list(method(n_iterations=2).animate(3, (32, 32), rng=0))
    np.testing.assert_array_equal(again[0].flow, kept)
    np.testing.assert_array_equal(again[1].image, second.image)


@pytest.mark.parametrize("renewal", [1, 2, 3])
def test_layers_must_live_long_enough_to_move(renewal):
    with pytest.raises(InputError, match="renewal must be 0"):
        list(method(renewal=renewal, n_iterations=2).animate(3, (32, 32), rng=0))


def test_an_odd_renewal_alternates_its_half_lives():
    from texsyn.drivers.fluid import _births

    births = _births(30, 5, loop=False)
    assert births[:6] == [0, 2, 5, 7, 10, 12] and births[-1] >= 30
    assert _births(30, 4, loop=False)[:4] == [0, 2, 4, 6]
    looped = _births(30, 7, loop=True)
    assert looped[0] == 0 and looped[-1] == 30 and len(looped) == 10


def test_the_default_speed_moves_the_texture_over_half_a_pixel_per_frame():
    tau = method().tau
    for seed in (0, 1):
        displacement = np.mean([np.mean(np.linalg.norm(tau * v, axis=-1)) for v in default_flows(seed)])
        assert displacement > 0.5, displacement  # 0.90 .. 0.91 (1 pixel per frame RMS)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_flow_evolves_at_default_settings(seed):
    flows = default_flows(seed)
    cosine = np.mean(np.abs(np.sum(unit(flows[0]) * unit(flows[-1]), axis=-1)))
    # mean |cos| between the first and last directions after 300 frames, seeds 0-2:
    # 0.58 .. 0.67 at 64x64, 0.61 .. 0.65 at 256x256 (independent fields: 2 / pi = 0.64)
    assert cosine < 0.8, cosine
    for v in flows[:: N_FRAMES // 6]:
        assert np.abs(divergence(v)).max() < 1e-10


# ---------------------------------------------------------------------- loops
@pytest.mark.method("animate")
def test_a_loop_keeps_the_statistics_and_wraps_like_any_other_step():
    run = video(2, 60, 20)
    assert len(run) == 60
    tau = video_method().tau
    steps = [mad(run[t].image, advect(run[t - 1].image, run[t - 1].flow, tau, order=3)) for t in range(1, 60)]
    wrap = mad(run[0].image, advect(run[-1].image, run[-1].flow, tau, order=3))
    # the wrap-around step against the others: 0.8 .. 1.2 of their median
    assert wrap <= 1.5 * np.median(steps), (wrap, np.median(steps))
    for frame in run:  # no cross-fade: every frame, the closing ones too, keeps its bands
        # largest deviation over the 60 frames: 0.10
        assert np.all(np.abs(detail_ratios(frame.image, GRASS) - 1) <= 0.12), (
            frame.index,
            detail_ratios(frame.image, GRASS),
        )


def test_the_loop_driver_comes_back_exactly_to_its_first_frame():
    rng = np.random.default_rng(0)
    dynamics = FlowDynamics(speed=1.0, turbulence=0.2, scale=16.0)
    initial = spectral_velocity((24, 24), rng, scale=16.0)

    def velocities():
        return looped_flow_sequence(initial, 30, 8, dynamics, np.random.default_rng(1))

    layers = np.random.default_rng(2)
    frames = list(
        texture_frames(
            velocities,
            30,
            synthesize=lambda v: layers.random((24, 24, 1)),
            project_texture=lambda x, v: x + 0.01 * v[..., :1],
            mean=np.array([0.5]),
            tau=0.5,
            renewal=12,
            loop=True,
            wrap_frame=True,
        )
    )
    assert len(frames) == 31
    np.testing.assert_array_equal(frames[30][0], frames[0][0])
    np.testing.assert_array_equal(frames[30][1], frames[0][1])
    assert not np.array_equal(frames[15][0], frames[0][0])


@pytest.mark.parametrize("closing", [1, 2, 10])
def test_the_looped_flow_returns_to_its_start_smoothly(closing):
    rng = np.random.default_rng(3)
    dynamics = FlowDynamics(speed=1.0, turbulence=0.2, scale=16.0)
    initial = spectral_velocity((32, 32), rng, scale=16.0)
    flows = list(looped_flow_sequence(initial, 40, closing, dynamics, rng))
    steps = [rms_speed(flows[t + 1] - flows[t]) for t in range(39)] + [rms_speed(flows[0] - flows[-1])]
    free = max(steps[: 39 - closing])  # the simulated steps before the steering
    # steering over c frames moves the blend weight by at most 1.5 / (c + 1) a step, between
    # fields that differ by at most twice the RMS velocity: even a one-frame closing takes
    # the jump in two halves
    limit = max(1.5 * free, 2.0 * dynamics.velocity * 1.5 / (closing + 1))
    assert max(steps[39 - closing :]) <= limit, (steps[39 - closing :], limit)
    for v in flows:
        assert np.abs(divergence(v)).max() < 1e-10
        assert rms_speed(v) == pytest.approx(dynamics.velocity, rel=0.05)


def test_loop_needs_renewed_layers():
    with pytest.raises(ValueError, match="advection='layers'"):
        list(method(advection="paper", n_iterations=2).animate(6, (32, 32), rng=0, loop=2))


def test_the_papers_literal_loop_still_runs():
    frames = list(method(advection="paper", n_iterations=2).animate(4, (32, 32), rng=0))
    assert len(frames) == 4 and frames[-1].image.shape == (32, 32)


# ---------------------------------------------------------------------- building blocks
def test_the_method_synthesises_with_the_tight_frame_of_section_2_2():
    model = method().model_
    transform = model.transform(periodic_tiling(model.flow, (32, 32)))
    assert isinstance(transform.grouplets, GroupletTightFrame) and transform.normalized
    image = np.random.default_rng(0).random((32, 32, 1))
    coefficients = transform.analyse(image)  # (L+1, J+1, 1, H, W), normalised
    d = coefficients * transform.grouplets.scales.reshape((-1, 1, 1) + (32, 32))
    bands = transform.pyramid.forward_planes(np.moveaxis(image, -1, 0))
    for j in range(bands.shape[0]):  # the tight frame's energy identity, band by band
        energy = transform.grouplets.energy(d[:, j, 0])
        assert energy == pytest.approx(np.sum(bands[j] ** 2), rel=1e-10)
    np.testing.assert_allclose(transform.synthesise(coefficients), image, atol=1e-10)


def test_layers_are_sampled_once_from_their_reference():
    """A coordinate map carried by the flow: no blur accumulates, unlike advecting the pixels."""
    rng = np.random.default_rng(0)
    image = rng.random((32, 32))
    step = 0.5 * spectral_velocity((32, 32), rng, scale=16.0)
    there = np.zeros((32, 32, 2))
    for _ in range(20):
        there = advect_displacement(there, step)
    moved = image
    for _ in range(20):
        moved = advect(moved, step, 1.0, order=1)
    # white noise keeps 0.9 of its deviation through one cubic interpolation, 0.5 through 20
    # bilinear ones
    once = np.std(sample_displaced(prefilter(image), there))
    assert once > 0.85 * np.std(image) and once > 1.4 * np.std(moved), (once, np.std(moved))
    # a constant flow moves the map by whole pixels exactly
    shift = np.zeros((32, 32, 2))
    shift[..., 1] = 1.0
    np.testing.assert_allclose(
        sample_displaced(prefilter(image), advect_displacement(shift * 0, shift)),
        np.roll(image, 1, axis=1),
        atol=1e-12,
    )


def test_initial_flows_are_divergence_free_with_the_asked_scale():
    rng = np.random.default_rng(0)
    for scale in (8.0, 32.0):
        v = spectral_velocity((128, 128), rng, scale=scale)
        assert np.abs(divergence(v)).max() < 1e-10 and rms_speed(v) == pytest.approx(1.0)
        power = np.sum(np.abs(np.fft.fft2(v, axes=(0, 1))) ** 2, axis=-1)
        k = np.hypot(*np.meshgrid(np.fft.fftfreq(128), np.fft.fftfreq(128), indexing="ij"))
        shells = np.bincount(np.minimum(k * 128, 64).astype(int).ravel(), weights=power.ravel(), minlength=65)
        assert abs(np.argmax(shells[1:]) + 1 - 128 / scale) <= 0.35 * 128 / scale
    steep = spectral_velocity((128, 128), np.random.default_rng(1), scale=16.0, slope=6.0)
    shallow = spectral_velocity((128, 128), np.random.default_rng(1), scale=16.0, slope=5 / 3)
    gradient = [np.mean((np.roll(x, -1, 0) - x) ** 2) for x in (steep, shallow)]
    assert gradient[0] < gradient[1]  # a shallower spectrum has more small eddies
    vortices = vortex_velocity((64, 64), rng, scale=8.0)
    assert np.abs(divergence(vortices)).max() < 1e-10 and rms_speed(vortices) == pytest.approx(1.0)


def test_forcing_keeps_the_flow_turning_at_the_set_speed():
    rng = np.random.default_rng(0)
    initial = spectral_velocity((48, 48), rng, scale=24.0)
    calm = list(
        flow_sequence(initial, 80, FlowDynamics(turbulence=0.0, scale=24.0), np.random.default_rng(1))
    )
    forced = list(
        flow_sequence(initial, 80, FlowDynamics(turbulence=0.2, scale=24.0), np.random.default_rng(1))
    )
    for flows in (calm, forced):
        assert all(rms_speed(v) == pytest.approx(2.0) for v in flows)  # speed 1 px/frame, tau 0.5
    cos = [np.mean(np.abs(np.sum(unit(f[0]) * unit(f[-1]), axis=-1))) for f in (calm, forced)]
    assert cos[1] < cos[0], cos
    decaying = list(flow_sequence(initial, 40, FlowDynamics(keep_speed=False, viscosity=1.0), rng))
    assert rms_speed(decaying[-1]) < 0.9 * rms_speed(decaying[0])


def test_the_learned_flow_repeats_without_a_seam_at_any_size():
    model = method().model_
    for shape in ((96, 96), (70, 50)):
        field = periodic_tiling(model.flow, shape)
        assert field.shape == shape + (2,)
        orientation = np.arctan2(field[..., 1], field[..., 0])
        doubled = np.exp(2j * orientation)
        # the jump across the wrap-around is no larger than across any other row or column
        rows = np.abs(np.diff(doubled, axis=0, append=doubled[:1]))
        cols = np.abs(np.diff(doubled, axis=1, append=doubled[:, :1]))
        assert rows[-1].mean() <= 2.5 * rows[:-1].mean(axis=1).max() / 2 + rows.mean()
        assert cols[:, -1].mean() <= 2.5 * cols[:, :-1].mean(axis=0).max() / 2 + cols.mean()
    np.testing.assert_array_equal(periodic_tiling(model.flow, (96, 96)), np.tile(model.flow, (2, 2, 1)))


def test_a_stretched_flow_stays_tangent_to_its_stretched_pattern():
    diagonal = np.full((32, 32, 2), np.sqrt(0.5))  # lines at 45 degrees
    field = periodic_tiling(diagonal, (48, 40))  # two tiles squeezed to 3/4, one stretched to 5/4
    expected = unit(np.array([0.75, 1.25]))
    np.testing.assert_allclose(np.abs(field), np.broadcast_to(expected, field.shape), atol=1e-12)


def test_a_static_synthesis_has_no_seam_at_a_size_the_exemplar_does_not_divide():
    out = method(n_iterations=6).sample((70, 50), rng=0)
    _, coherence = structure_tensor_orientation(out)
    assert out.shape == (70, 50) and np.isfinite(out).all()
    wrapped = np.roll(np.roll(out, 35, axis=0), 25, axis=1)  # the seam, if any, moves inside
    edges = [np.abs(np.diff(x.astype(np.float64), axis=0)).mean(axis=1) for x in (out, wrapped)]
    assert edges[1][34] <= 2.0 * np.median(edges[0])
