"""Tests written for mutants that survived the mutation runs (docs/testing.md).

Each test states a property of the algorithm that the method's own tests did not pin down
(found by ``python benchmarks/mutation.py``): the K-SVD rule for unused atoms, the terms of
the sparse energy, colour and non-square outputs of the sparse synthesis, the local
refinement of the DT-CWT sampling, and for the grouplets the named flows, the structure
tensor's coherence, ``rescale_speed``, the looped animation, the default time step, ``sigma``,
``orient_field``'s start and the periodic initial flow; for the patch-valued wavelets
``random_state``, ``max_resolution``, the window widths, the minimum exemplar, the coordinate-map
bounds and LLE's neighbour-graph repair.
"""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest
from scipy import ndimage

import texsyn
from conftest import FAST_PARAMS
from texsyn.errors import InputError
from texsyn.methods.wavelet_sampling import block_indices
from texsyn.ops import HistogramMatcher, extract_patches
from texsyn.ops.color import ColorPCA
from texsyn.ops.flow import builtin_flow, structure_tensor_orientation
from texsyn.ops.fluid import rescale_speed
from texsyn.ops.sparse import batch_omp, image_energy, ksvd
from texsyn.ops.sparse import box_power as _box_power


# ----------------------------------------------------------------------------- sparse
def test_ksvd_replaces_unused_atoms_by_patch_directions():
    """Patches along 4 directions, 6 atoms, 1-sparse codes: some atoms are unused (two start
    on the same direction) and are replaced by a worst-approximated patch, so every learned
    atom is one of the directions and every patch is coded exactly."""
    rng = np.random.default_rng(0)
    directions = np.linalg.qr(rng.standard_normal((12, 4)))[0]
    labels = rng.integers(4, size=300)
    amplitudes = rng.uniform(0.5, 2.0, 300) * rng.choice([-1.0, 1.0], 300)
    patches = directions[:, labels] * amplitudes
    d = ksvd(patches, 6, 1, n_iterations=3, max_training=300, rng=np.random.default_rng(1))
    np.testing.assert_allclose(np.abs(d.T @ directions).max(axis=1), 1.0, atol=1e-9)
    codes = batch_omp(d, patches, 1)
    assert np.linalg.norm(patches - d @ codes) <= 1e-9 * np.linalg.norm(patches)


def energy_setup():
    rng = np.random.default_rng(3)
    u = rng.random((16, 16, 1))
    reference = rng.random((16, 16, 1))
    tau, step = 4, 2
    patches, _ = extract_patches(u, tau, stride=step, mode="periodic")
    coded = patches + 0.1 * rng.standard_normal(patches.shape)
    projector = HistogramMatcher([np.sort(rng.random(256))], 256)
    power = _box_power((16, 16), tau)

    def energy(alpha, beta):
        return image_energy(
            u, coded, tau, step, projector, alpha=alpha, beta=beta, box_power=power, reference=reference
        )

    return u, reference, tau, projector, energy


def test_sparse_energy_data_term_of_another_images_patches_is_the_pixel_distance():
    """With periodic patches every pixel lies in (tau/step)^2 of them, so the normalised data
    term (1/Z)||Pi(u) - Pi(v)||^2 is the squared pixel distance ||u - v||^2."""
    rng = np.random.default_rng(4)
    u, v = rng.random((16, 16, 1)), rng.random((16, 16, 1))
    tau, step = 4, 2
    coded, _ = extract_patches(v, tau, stride=step, mode="periodic")
    projector = HistogramMatcher([np.sort(rng.random(256))], 256)
    energy = image_energy(
        u, coded, tau, step, projector, alpha=0.0, beta=0.0, box_power=_box_power((16, 16), tau), reference=v
    )
    np.testing.assert_allclose(energy, np.sum((u - v) ** 2), rtol=1e-10)


def test_sparse_energy_is_affine_in_alpha_with_the_histogram_distance_as_slope():
    """Energy (6) of Tartavel et al.: E = data + alpha * ||u - T_hist(u)||^2 + beta * low."""
    u, _, _, projector, energy = energy_setup()
    slope = np.sum((u - projector(u, None)) ** 2)
    assert slope > 0
    np.testing.assert_allclose(energy(1.0, 0.0) - energy(0.0, 0.0), slope, rtol=1e-10)
    np.testing.assert_allclose(energy(3.0, 0.0) - energy(0.0, 0.0), 3.0 * slope, rtol=1e-10)


def test_sparse_energy_low_frequency_term_is_the_box_filtered_difference():
    """beta's term is ||h * (u - u_ref)||^2 for the tau x tau box h (periodic): computed here
    by direct filtering in the image domain instead of the Fourier domain."""
    u, reference, tau, _, energy = energy_setup()
    filtered = ndimage.uniform_filter((u - reference)[..., 0], tau, mode="wrap")
    np.testing.assert_allclose(energy(0.0, 1.0) - energy(0.0, 0.0), np.sum(filtered**2), rtol=1e-10)
    np.testing.assert_allclose(energy(0.0, 2.5) - energy(0.0, 0.0), 2.5 * np.sum(filtered**2), rtol=1e-10)


def test_sparse_colour_output_has_the_exemplars_values_in_its_colour_pca_axes(colour_exemplar):
    """Colour is handled in the exemplar's PCA axes: with the final histogram step, an output
    of the exemplar's size has exactly the exemplar's values along each axis."""
    method = texsyn.make_method("sparse", **FAST_PARAMS["sparse"]).fit(colour_exemplar)
    out = method.sample(colour_exemplar.shape[:2], rng=0)
    assert out.shape == colour_exemplar.shape
    pca = ColorPCA(colour_exemplar.astype(np.float64))
    want = np.sort(pca.forward(colour_exemplar.astype(np.float64)).reshape(-1, 3), axis=0)
    got = np.sort(pca.forward(out.astype(np.float64)).reshape(-1, 3), axis=0)
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_sparse_tall_output_and_aligned_reference_fallback(grey_exemplar):
    """A non-square output taller than the exemplar has its shape on every scale, and
    lowpass_ref='aligned' (which needs an output within the exemplar) falls back to the mean
    with a warning; within the exemplar it is used without one."""
    params = {**FAST_PARAMS["sparse"], "lowpass_ref": "aligned"}
    method = texsyn.make_method("sparse", **params).fit(grey_exemplar)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert method.sample((24, 16), rng=0).shape == (24, 16)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = method.sample((48, 24), rng=0)
    assert out.shape == (48, 24)
    assert any("aligned" in str(w.message) for w in caught)
    # the final histogram step: the output's values are the exemplar's quantiles
    quantiles = np.quantile(grey_exemplar, np.linspace(0, 1, 11))
    np.testing.assert_allclose(np.quantile(out, np.linspace(0, 1, 11)), quantiles, atol=0.05)


# ----------------------------------------------------------------------------- cwt
def identity_maps(levels: int, side: int) -> list[np.ndarray]:
    """Source maps of an exact copy of the exemplar, from level 1 to ``levels``."""
    top = side // 2**levels
    cells = np.stack(np.mgrid[:top, :top], axis=-1)
    return [block_indices(cells, 2 ** (levels - k)) for k in range(1, levels + 1)]


def test_cwt_refinement_keeps_an_exact_copy_exact():
    exemplar = texsyn.data.exemplar("brick", size=40)
    method = texsyn.make_method("cwt", levels=3, window=3, seed="exemplar", refine=True, refine_radius=2)
    result = method.fit(exemplar).sample_with_map((40, 40), rng=0)
    np.testing.assert_array_equal(result.image, exemplar)
    np.testing.assert_array_equal(result.source_map, np.stack(np.mgrid[:40, :40], axis=-1))


@pytest.mark.parametrize("levels", [2, 3])
def test_cwt_refinement_moves_isolated_misplaced_coefficients_back(levels):
    """The local re-search compares each coefficient's neighbourhood with the exemplar's
    around its source and the sources within refine_radius: a coefficient copied from one
    position off (its neighbours being right) goes back to its true source, on the border
    too; a coarser misplaced block is corrected and handed down to its children."""
    exemplar = texsyn.data.exemplar("brick", size=64)
    method = texsyn.make_method("cwt", levels=levels, window=3, refine=True, refine_radius=1).fit(exemplar)
    truth = identity_maps(levels, 64)
    maps = [m.copy() for m in truth]
    last = maps[0].shape[0] - 1
    points = [(5, 9), (20, 3), (0, 12), (last, last), (14, 0), (last, 0), (0, last)]
    for i, j in points:
        maps[0][i, j] = np.clip(maps[0][i, j] + (1 if i < last else -1, -1 if j > 0 else 1), 0, last)
    if levels == 3:
        for i, j in [(3, 4), (0, 0)]:  # a level-2 coefficient and its four children, from a wrong source
            source = maps[1][i, j] + (1, 1)
            maps[1][i, j] = source
            maps[0][2 * i : 2 * i + 2, 2 * j : 2 * j + 2] = 2 * source + np.stack(np.mgrid[:2, :2], axis=-1)
    refined = method._refine(maps)
    for i, j in points:
        np.testing.assert_array_equal(refined[0][i, j], truth[0][i, j])
    if levels == 3:
        for level in range(levels):
            np.testing.assert_array_equal(refined[level], truth[level])


# ----------------------------------------------------------------------------- grouplets
def radial_and_tangential(field, centre, r_min=1.5, r_max=4.0):
    """Cosines of the field's vectors with the radius and with the counter-clockwise tangent
    (in (row, col) axes) on a ring around ``centre``."""
    h, w = field.shape[:2]
    r, c = np.mgrid[:h, :w].astype(np.float64)
    dr, dc = r - centre[0], c - centre[1]
    ring = (np.hypot(dr, dc) > r_min) & (np.hypot(dr, dc) < r_max)
    v = field[ring]
    p = np.stack([dr[ring], dc[ring]], axis=-1)
    norm = np.linalg.norm(v, axis=-1) * np.linalg.norm(p, axis=-1)
    return (v * p).sum(-1) / norm, (p[:, 0] * v[:, 1] - p[:, 1] * v[:, 0]) / norm


def test_builtin_sources_flow_leaves_its_sources_and_turns_around_its_vortices():
    """'sources': two sources at (1/4, 1/4) and (3/4, 3/4) of the frame, two vortices at
    (1/4, 3/4) and (3/4, 1/4), each with its own Gaussian envelope, on a periodic frame."""
    h, w = 64, 48
    field = builtin_flow("sources", (h, w))
    assert field.shape == (h, w, 2)
    for cr, cc, kind in (
        (0.25, 0.25, "source"),
        (0.75, 0.75, "source"),
        (0.25, 0.75, "vortex"),
        (0.75, 0.25, "vortex"),
    ):
        radial, tangential = radial_and_tangential(field, (cr * h, cc * w))
        if kind == "source":
            assert radial.min() > 0.99, (cr, cc)
        else:
            assert np.abs(radial).max() < 0.01 and tangential.min() > 0.99, (cr, cc)
    # wrapped displacements: the field is continuous across the frame's borders
    assert np.abs(field[0] - field[-1]).max() < 0.1
    assert np.abs(field[:, 0] - field[:, -1]).max() < 0.1


def test_builtin_waves_flow_is_a_sinuous_horizontal_flow():
    h, w = 20, 36
    field = builtin_flow("waves", (h, w))
    assert field.shape == (h, w, 2)
    np.testing.assert_array_equal(field[..., 1], 1.0)
    rows = field[..., 0]
    np.testing.assert_allclose(rows, np.broadcast_to(rows[:1], rows.shape))  # the same down every column
    np.testing.assert_allclose(rows[:, : w // 2], rows[:, w // 2 :], atol=1e-12)  # two periods
    np.testing.assert_allclose(rows.mean(axis=1), 0.0, atol=1e-12)
    assert 0.0 < np.abs(rows).max() < 1.0  # it bends, but always goes forward


def test_builtin_vortex_flow_turns_about_the_centre_pixel():
    h, w = 33, 47  # odd sides: the centre is a pixel
    field = builtin_flow("vortex", (h, w))
    r, c = np.mgrid[:h, :w]
    dr, dc = r - h // 2, c - w // 2
    np.testing.assert_array_equal(field[h // 2, w // 2], 0.0)
    np.testing.assert_allclose(field[..., 0] * dr + field[..., 1] * dc, 0.0, atol=1e-12)
    np.testing.assert_allclose(np.hypot(field[..., 0], field[..., 1]), np.hypot(dr, dc))


@pytest.mark.parametrize(
    "name, direction",
    [
        ("constant", (0.0, 1.0)),
        ("constant:90", (-1.0, 0.0)),
        ("Constant:180 ", (0.0, -1.0)),
        ("constant:-90", (1.0, 0.0)),
    ],
)
def test_builtin_constant_flow_points_at_its_angle(name, direction):
    """'constant:ANGLE': ANGLE degrees counter-clockwise from the +column axis (rows go down)."""
    field = builtin_flow(name, (5, 7))
    np.testing.assert_allclose(field, np.broadcast_to(direction, (5, 7, 2)), atol=1e-12)


@pytest.mark.parametrize("name", ["constant:abc", "constantx", "constant:nan", "constant:inf", "spiral"])
def test_builtin_flow_refuses_bad_names(name):
    with pytest.raises(InputError):
        builtin_flow(name, (5, 7))


def test_looped_animation_flows_are_the_simulation_shifted_then_steered_back_to_its_start(grey_exemplar):
    """loop=m: the flow of frame t is the plain simulation's flow of frame t + m (the loop
    starts after an m-frame run-up), until the last m frames, which blend it with the run-up
    (the simulation n frames earlier) with a weight that grows from 1/(m+1) (smoothstep) towards 1."""
    method = texsyn.make_method("grouplets", colour="grey", n_iterations=2, layer_iterations=2).fit(
        grey_exemplar
    )
    n, m, shape = 8, 3, (24, 16)
    simulated = list(method.animate(n + m, shape, rng=4))
    looped = list(method.animate(n, shape, rng=4, loop=m))
    assert [f.index for f in looped] == list(range(n))
    for f in looped[: n - m]:
        np.testing.assert_array_equal(f.flow, simulated[f.index + m].flow)
    weights = []
    for k, f in enumerate(looped[n - m :]):
        a, b = simulated[n + k].flow, simulated[k].flow
        # the blend is rescaled to the interpolated speed: compare directions of the blend
        w = np.sum((f.flow - a) * (b - a)) / np.sum((b - a) ** 2)
        weights.append(w)
    # smoothstep of 1/4, 2/4, 3/4: 0.16, 0.5, 0.84 (the speed rescaling moves them a little)
    assert 0.1 < weights[0] < 0.25 and all(x < y for x, y in itertools.pairwise(weights))
    assert weights[-1] < 1


def test_rescale_speed_sets_the_rms_speed_and_leaves_a_still_flow_still():
    rng = np.random.default_rng(5)
    velocity = rng.standard_normal((12, 10, 2))
    scaled = rescale_speed(velocity, 2.5)
    np.testing.assert_allclose(np.sqrt(np.mean(np.sum(scaled**2, axis=-1))), 2.5)
    np.testing.assert_allclose(scaled / np.linalg.norm(scaled), velocity / np.linalg.norm(velocity))
    still = rescale_speed(np.zeros((12, 10, 2)), 2.5)
    np.testing.assert_array_equal(still, 0.0)


def test_structure_tensor_coherence_is_one_on_stripes_and_low_on_noise():
    """Coherence (lambda+ - lambda-) / (lambda+ + lambda-): 1 where the image has one
    orientation (diagonal waves, so that the tensor's off-diagonal term matters), low on white
    noise; the orientation runs along the waves' crests."""
    r, c = np.mgrid[:48, :48]
    waves = np.sin(2 * np.pi * (r + c) / 8)  # crests along (1, -1)
    orientation, coherence = structure_tensor_orientation(waves)
    np.testing.assert_allclose(coherence, 1.0, atol=1e-6)
    np.testing.assert_allclose(np.abs(orientation @ np.array([1.0, -1.0])) / np.sqrt(2), 1.0, atol=1e-6)
    _, noisy = structure_tensor_orientation(np.random.default_rng(0).standard_normal((48, 48)))
    assert 0.0 < noisy.mean() < 0.2


# ----------------------------------------------------------------------------- grouplets (2)
def test_grouplets_default_time_step_is_one_half():
    """The documented default ``tau = 0.5``: the texture moves ``speed`` pixels per frame, so
    the velocity (pixels per time unit) of every frame has RMS ``speed / tau``, and an
    animation with the default equals one with ``tau=0.5``."""
    rng = np.random.default_rng(2)
    exemplar = ndimage.gaussian_filter(rng.random((16, 16)), 1.0, mode="wrap")
    params = dict(colour="grey", layer_iterations=1, levels=1, grouplet_levels=1, n_projections=0, speed=3.0)

    def frames(**extra):
        method = texsyn.make_method("grouplets", **params, **extra).fit(exemplar)
        return list(method.animate(2, rng=7))

    default, half, other = frames(), frames(tau=0.5), frames(tau=1.5)
    np.testing.assert_array_equal(default[1].image, half[1].image)
    for frame in default:
        assert np.sqrt(np.mean(np.sum(frame.flow**2, axis=-1))) == pytest.approx(6.0)
    assert np.sqrt(np.mean(np.sum(other[1].flow ** 2, axis=-1))) == pytest.approx(2.0)


def test_grouplets_sigma_sets_the_structure_tensor_smoothing_of_the_model():
    """``sigma`` is the structure tensor's integration scale: on white noise a wider window
    averages more isotropic gradients, so the learned coherence falls as sigma grows, and the
    model's geometry is the one of ``structure_tensor_orientation`` at that sigma."""
    from texsyn.ops import periodic_smooth_decomposition

    exemplar = np.random.default_rng(4).random((32, 32))
    coherence = {}
    for sigma in (1.0, 8.0):
        method = texsyn.make_method("grouplets", colour="grey", sigma=sigma, **FAST_PARAMS["grouplets"]).fit(
            exemplar
        )
        periodic = periodic_smooth_decomposition(exemplar.astype(np.float64))[0]
        _, expected = structure_tensor_orientation(periodic, sigma=sigma, presmooth=1.0)
        np.testing.assert_allclose(method.model_.coherence, expected, atol=1e-9)
        coherence[sigma] = method.model_.coherence.mean()
    assert coherence[8.0] < 0.5 * coherence[1.0]


def test_orient_field_takes_the_sign_of_its_start_vector():
    """A constant orientation with random signs becomes one direction everywhere: the one of
    the vector at ``start`` (the propagation never flips its start)."""
    from texsyn.ops.flow import orient_field

    rng = np.random.default_rng(0)
    signs = rng.choice([-1.0, 1.0], size=(12, 10))
    signs[0, 0], signs[6, 5] = 1.0, -1.0  # (6, 5) is the centre, the default start
    direction = np.array([0.6, 0.8])
    orientation = signs[..., None] * direction
    np.testing.assert_allclose(
        orient_field(orientation, start=(0, 0)), np.broadcast_to(direction, orientation.shape)
    )
    np.testing.assert_allclose(orient_field(orientation), np.broadcast_to(-direction, orientation.shape))
    np.testing.assert_allclose(
        orient_field(orientation, start=(6, 5)), np.broadcast_to(-direction, orientation.shape)
    )


def test_grouplets_random_initial_flow_is_periodic():
    """``initial_flow='noise'``: smoothed noise on the torus (the fluid solver is periodic),
    so across the wrap-around edge the flow changes no more than between neighbouring rows or
    columns inside; it is divergence-free and moves ``speed`` pixels per frame (RMS)."""
    from texsyn.ops.fluid import divergence

    method = texsyn.make_method("grouplets", initial_flow="noise", speed=1.5)
    for seed in range(3):
        v = method.initial_velocity((32, 24), np.random.default_rng(seed))
        assert np.abs(v[0] - v[-1]).max() <= np.abs(np.diff(v, axis=0)).max()
        assert np.abs(v[:, 0] - v[:, -1]).max() <= np.abs(np.diff(v, axis=1)).max()
        # 1.5 pixels per frame: RMS speed / tau = 3 pixels per time unit
        np.testing.assert_allclose(np.sqrt(np.mean(np.sum(v**2, axis=-1))), 3.0)
        assert np.abs(divergence(v)).max() < 1e-6 * np.abs(v).max()


# ----------------------------------------------------------------------------- patch_wavelet
def test_patch_wavelet_random_state_seeds_the_embedding():
    """``random_state`` seeds the LLE eigen-solver (ARPACK above 512 positions): the same
    state gives the same embedding, another one an embedding of the same manifold whose
    coordinates may differ (here: by their signs; mirrored, since the patches of the brick
    wrapped around its border have nearly equal eigenvalues, whose coordinates another start
    vector rotates, not only flips)."""
    exemplar = texsyn.data.exemplar("brick", size=40)  # 1600 positions: ARPACK

    def embedding(state):
        method = texsyn.make_method("patch_wavelet", random_state=state, exemplar_boundary="symmetric")
        return method.fit(exemplar).transform_.embedding(8)[0]

    first, again, other = embedding(0), embedding(0), embedding(1)
    np.testing.assert_array_equal(first, again)
    assert not np.allclose(first, other)
    np.testing.assert_allclose(np.abs(np.sum(first * other, axis=0)) / first.shape[0], 1.0, atol=1e-3)


def test_patch_wavelet_max_resolution_sets_the_block_means_of_wide_windows():
    """``max_resolution=4``: a window of width 8 is described by its 4x4 means of 2x2 blocks
    (16 values per channel, not 64), the means of the full 8x8 window's blocks."""
    from texsyn.models.patch_wavelet import ExemplarWindows

    exemplar = texsyn.data.exemplar("brick", size=32)
    transform = (
        texsyn.make_method("patch_wavelet", max_resolution=4, exemplar_boundary="periodic")
        .fit(exemplar)
        .transform_
    )
    assert transform.windows.dimension(8) == 16
    rows, cols = np.array([0, 5, 31]), np.array([3, 17, 30])
    coarse = transform.windows.descriptors(rows, cols, 8)
    full = ExemplarWindows(exemplar, "periodic", max_resolution=8).descriptors(rows, cols, 8)
    assert coarse.shape == (3, 16) and full.shape == (3, 64)
    blocks = full.reshape(3, 4, 2, 4, 2).mean(axis=(2, 4)).reshape(3, 16)
    np.testing.assert_allclose(coarse, blocks, atol=1e-9)


@pytest.mark.parametrize(
    ("min_width", "max_width", "expected"),
    [(2, None, [2, 4, 8, 16, 32, 32]), (8, None, [8, 8, 8, 16, 32, 32]), (2, 16, [2, 4, 8, 16, 16, 16])],
)
def test_patch_wavelet_window_width_doubles_per_level_between_its_bounds(min_width, max_width, expected):
    """Level j uses ``clamp(2^j, min_width, max_width)``, max_width at most half the exemplar."""
    from texsyn.models.patch_wavelet import PatchWaveletTransform

    transform = PatchWaveletTransform(
        texsyn.data.exemplar("brick", size=64), min_width=min_width, max_width=max_width
    )
    assert [transform.width(level) for level in range(1, 7)] == expected


@pytest.mark.parametrize(("min_width", "feature_width", "side"), [(8, 8, 16), (16, 8, 32), (4, 8, 8)])
def test_patch_wavelet_minimum_exemplar_is_two_patch_widths(min_width, feature_width, side):
    """The smallest exemplar holds two patches of ``min_width`` (and one feature window):
    an exemplar of that side is fitted, one pixel less is refused."""
    exemplar = texsyn.data.exemplar("brick", size=32)
    method = texsyn.make_method("patch_wavelet", min_width=min_width, feature_width=feature_width)
    assert method.min_exemplar_size()[0] == side
    method.fit(exemplar[:side, :side])
    with pytest.raises(InputError, match="too small"):
        method.fit(exemplar[: side - 1, : side - 1])


def test_patch_wavelet_coordinate_map_must_stay_inside_the_exemplar():
    """``forward`` accepts any map of exemplar positions with power-of-two sides >= 2 (a 2x2
    map and a 2x4 map at the exemplar's last row and column included) and refuses a map with a
    row or (alone) a column outside the exemplar, or a side that is not a power of two."""
    exemplar = texsyn.data.exemplar("brick", size=16)
    transform = texsyn.make_method("patch_wavelet", min_width=2, embedding_dim=2).fit(exemplar).transform_
    h, w = transform.exemplar_shape
    inside = np.array([[[0, 0], [h - 1, w - 1]], [[3, w - 1], [h - 1, 0]]])
    transform.forward(inside)
    transform.forward(np.concatenate([inside, inside[:, ::-1]], axis=1))
    for bad in ((0, w), (h, 0), (-1, 0), (0, -1)):
        coords = inside.copy()
        coords[1, 1] = bad
        with pytest.raises(ValueError, match="outside the exemplar"):
            transform._check_map(coords)
    with pytest.raises(ValueError, match="powers of two"):
        transform._check_map(np.zeros((3, 4, 2), dtype=int))
    with pytest.raises(ValueError, match="powers of two"):
        transform._check_map(np.zeros((1, 4, 2), dtype=int))


def test_lle_grows_the_neighbourhood_until_the_graph_is_connected():
    """Two far-apart triples and ``n_neighbors=2``: the 2-NN graph has two parts, so LLE
    enlarges the neighbourhood (by 4, capped at n - 1 = 5) until it is connected, says so,
    and its 1-D embedding separates the triples."""
    from texsyn.models.patch_wavelet import lle_embedding

    rng = np.random.default_rng(0)
    X = np.concatenate([rng.normal(0.0, 0.1, (3, 4)), rng.normal(5.0, 0.1, (3, 4))])
    with pytest.warns(UserWarning, match=r"needed 5 neighbours \(not 2\) to be connected"):
        Y = lle_embedding(X, (2, 3), n_components=1, n_neighbors=2)
    assert Y.shape == (6, 1) and np.all(np.isfinite(Y))
    assert np.sign(Y[:3, 0]).tolist() == [np.sign(Y[0, 0])] * 3
    assert np.sign(Y[3:, 0]).tolist() == [-np.sign(Y[0, 0])] * 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # connected from the start: no enlargement
        lle_embedding(X, (2, 3), n_components=1, n_neighbors=5)
