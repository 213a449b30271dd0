"""Tests written for mutants that survived the mutation runs (docs/testing.md).

Each test states a property of the algorithm that the method's own tests did not pin down
(found by ``python benchmarks/mutation.py``): the K-SVD rule for unused atoms, the terms of
the sparse energy, colour and non-square outputs of the sparse synthesis, the local
refinement of the DT-CWT sampling, and for the grouplets the named flows, the structure
tensor's coherence, ``rescale_speed`` and the looped animation.
"""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest
from conftest import FAST_PARAMS
from scipy import ndimage

import texsyn
from texsyn.errors import InputError
from texsyn.methods.sparse import _box_power, image_energy
from texsyn.methods.wavelet_sampling import block_indices
from texsyn.ops import HistogramMatcher, extract_patches
from texsyn.ops.color import ColorPCA
from texsyn.ops.flow import builtin_flow, structure_tensor_orientation
from texsyn.ops.fluid import rescale_speed
from texsyn.ops.sparse import batch_omp, ksvd


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
        return image_energy(u, coded, tau, step, projector, alpha=alpha, beta=beta, box_power=power, reference=reference)

    return u, reference, tau, projector, energy


def test_sparse_energy_data_term_of_another_images_patches_is_the_pixel_distance():
    """With periodic patches every pixel lies in (tau/step)^2 of them, so the normalised data
    term (1/Z)||Pi(u) - Pi(v)||^2 is the squared pixel distance ||u - v||^2."""
    rng = np.random.default_rng(4)
    u, v = rng.random((16, 16, 1)), rng.random((16, 16, 1))
    tau, step = 4, 2
    coded, _ = extract_patches(v, tau, stride=step, mode="periodic")
    projector = HistogramMatcher([np.sort(rng.random(256))], 256)
    energy = image_energy(u, coded, tau, step, projector, alpha=0.0, beta=0.0,
                          box_power=_box_power((16, 16), tau), reference=v)
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
    for cr, cc, kind in ((0.25, 0.25, "source"), (0.75, 0.75, "source"), (0.25, 0.75, "vortex"), (0.75, 0.25, "vortex")):
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


@pytest.mark.parametrize("name, direction", [("constant", (0.0, 1.0)), ("constant:90", (-1.0, 0.0)),
                                             ("Constant:180 ", (0.0, -1.0)), ("constant:-90", (1.0, 0.0))])
def test_builtin_constant_flow_points_at_its_angle(name, direction):
    """'constant:ANGLE': ANGLE degrees counter-clockwise from the +column axis (rows go down)."""
    field = builtin_flow(name, (5, 7))
    np.testing.assert_allclose(field, np.broadcast_to(direction, (5, 7, 2)), atol=1e-12)


@pytest.mark.parametrize("name", ["constant:abc", "constantx", "constant:nan", "constant:inf", "spiral"])
def test_builtin_flow_refuses_bad_names(name):
    with pytest.raises(InputError):
        builtin_flow(name, (5, 7))


def test_looped_animation_is_the_simulation_shifted_with_a_crossfade_back_to_its_start(grey_exemplar):
    """loop=m: the n frames are simulated frames m .. n+m-1 (same seed), and each of the last
    m is a blend of simulated frame n+k and frame k whose weight on frame k grows with k."""
    method = texsyn.make_method("grouplets", colour="grey", n_iterations=2, speed=2.0).fit(grey_exemplar)
    n, m, shape = 6, 3, (24, 16)
    simulated = list(method.animate(n + m, shape, rng=4))
    looped = list(method.animate(n, shape, rng=4, loop=m))
    assert [f.index for f in looped] == list(range(n))
    for f in looped[: n - m]:
        np.testing.assert_array_equal(f.image, simulated[f.index + m].image)
        np.testing.assert_array_equal(f.flow, simulated[f.index + m].flow)
    weights = []
    for k, f in enumerate(looped[n - m :]):
        assert f.image.shape == shape
        for got, a, b in ((f.image, simulated[n + k].image, simulated[k].image), (f.flow, simulated[n + k].flow, simulated[k].flow)):
            a, b, got = (np.asarray(x, dtype=np.float64) for x in (a, b, got))
            w = np.sum((got - a) * (b - a)) / np.sum((b - a) ** 2)
            np.testing.assert_allclose(got, a + w * (b - a), atol=1e-5)
            weights.append(w)
    image_weights = weights[0::2]
    np.testing.assert_allclose(weights[1::2], image_weights, atol=1e-6)  # image and flow blend alike
    assert 0 < image_weights[0] and all(x < y for x, y in itertools.pairwise(image_weights)) and image_weights[-1] < 1


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
