"""The grouplet tight frame of Peyré 2008, section 2.2: the properties the paper states."""

import numpy as np
import pytest

from texsyn.ops.flow import association_fields, builtin_flow
from texsyn.transforms.grouplet_frame import GroupletTightFrame, grouplet_weights

SHAPE = (24, 24)
N = SHAPE[0] * SHAPE[1]


def converging(levels: int, seed: int = 0) -> np.ndarray:
    """Random many-to-one associations (many pixels share a target, some point to themselves)."""
    rng = np.random.default_rng(seed)
    a = rng.integers(0, N // 4, size=(levels, N))
    a[:, :10] = np.arange(10)  # self-associations
    return a


def fields() -> dict[str, np.ndarray]:
    return {
        "vortex": association_fields(builtin_flow("vortex", SHAPE), 4),
        "sources": association_fields(builtin_flow("sources", SHAPE), 4),
        "constant": association_fields(builtin_flow("constant:0", SHAPE), 4),
        "converging": converging(4),
        "identity": np.tile(np.arange(N), (3, 1)),
    }


@pytest.mark.parametrize("name", list(fields()))
def test_grouplet_frame_energy_is_conserved_with_the_tau_weights(name):
    """Tight frame: sum_l tau_l ||d_l||^2 = ||f||^2, also where associations converge."""
    frame = GroupletTightFrame(fields()[name], SHAPE)
    image = np.random.default_rng(1).standard_normal(SHAPE)
    d = frame.forward(image)
    weighted = sum(t * np.sum(d[level] ** 2) for level, t in enumerate(grouplet_weights(frame.levels)))
    assert weighted == pytest.approx(np.sum(image**2), rel=1e-12)
    assert frame.energy(d) == pytest.approx(np.sum(image**2), rel=1e-12)


def test_grouplet_frame_tau_weights_are_the_papers():
    assert grouplet_weights(4).tolist() == [1.0, 0.5, 0.25, 0.125, 0.125]
    assert grouplet_weights(1).tolist() == [1.0, 1.0]


@pytest.mark.parametrize("name", list(fields()))
def test_grouplet_frame_reconstructs_exactly_by_the_tau_formula(name):
    """inverse(forward(f)) = f, and inverse is f = sum_l tau_l sum_m d_l(m) b_{l,m} with b_{l,m} = rows of forward."""
    frame = GroupletTightFrame(fields()[name], SHAPE)
    image = np.random.default_rng(2).random(SHAPE)
    assert np.max(np.abs(frame.inverse(frame.forward(image)) - image)) < 1e-12
    # inverse of arbitrary coefficients = the tau-weighted synthesis with the atoms b_{l,m} = Phi^T e_{l,m}
    small = (6, 6)
    n = small[0] * small[1]
    assoc = np.random.default_rng(3).integers(0, n // 3, size=(3, n))
    frame = GroupletTightFrame(assoc, small)
    phi = frame.forward(
        np.eye(n).reshape((n,) + small)
    )  # (L+1, n_images=n, H, W): phi[l, k, m] = <e_k, b_{l,m}>
    atoms = np.moveaxis(phi.reshape(frame.levels + 1, n, n), 1, 2)  # atoms[l, m] = b_{l,m}
    coeffs = np.random.default_rng(4).standard_normal((frame.levels + 1, n))
    synthesis = sum(frame.tau[level] * coeffs[level] @ atoms[level] for level in range(frame.levels + 1))
    assert (
        np.max(np.abs(frame.inverse(coeffs.reshape((frame.levels + 1,) + small)).ravel() - synthesis)) < 1e-12
    )
    # Parseval operator identity: sum_l tau_l Phi_l^T Phi_l = I
    gram = sum(frame.tau[level] * atoms[level].T @ atoms[level] for level in range(frame.levels + 1))
    assert np.max(np.abs(gram - np.eye(n))) < 1e-12


def test_grouplet_frame_is_linear_and_takes_batches():
    frame = GroupletTightFrame(fields()["sources"], SHAPE)
    rng = np.random.default_rng(5)
    f, g = rng.standard_normal(SHAPE), rng.standard_normal(SHAPE)
    assert np.allclose(
        frame.forward(2.0 * f - 3.0 * g), 2.0 * frame.forward(f) - 3.0 * frame.forward(g), atol=1e-12
    )
    c1, c2 = rng.standard_normal((2, frame.levels + 1) + SHAPE)
    assert np.allclose(frame.inverse(c1 + 0.5 * c2), frame.inverse(c1) + 0.5 * frame.inverse(c2), atol=1e-12)
    batch = frame.forward(np.stack([f, g]))
    assert batch.shape == (frame.levels + 1, 2) + SHAPE
    assert np.allclose(batch[:, 1], frame.forward(g))
    assert np.allclose(frame.inverse(batch), np.stack([f, g]))


@pytest.mark.parametrize("name", list(fields()))
def test_grouplet_frame_constant_image_has_zero_details(name):
    frame = GroupletTightFrame(fields()[name], SHAPE)
    d = frame.forward(np.full(SHAPE, 3.0))
    assert np.max(np.abs(d[:-1])) < 1e-12
    # the low-pass is proportional to the residual (= 3): d_L = sqrt(s_L / 2) * 3
    assert np.allclose(d[-1].ravel(), np.sqrt(frame.masses[-1] / 2.0) * 3.0)


def test_grouplet_frame_along_a_constant_flow_is_undecimated_haar():
    """A_l(r, c) = (r, c + 2^l): masses 2^l, details 2^((l-2)/2) (a_l(m) - a_l(m + 2^l)), a_(l+1) the pair average."""
    assoc = association_fields(builtin_flow("constant:0", SHAPE), 3)
    cols = np.arange(SHAPE[1])
    for level in range(3):
        expected = (np.arange(SHAPE[0])[:, None] * SHAPE[1] + (cols[None, :] + 2**level) % SHAPE[1]).ravel()
        assert np.array_equal(assoc[level], expected)
    frame = GroupletTightFrame(assoc, SHAPE)
    for level in range(4):
        assert np.all(frame.masses[level] == 2.0**level)
    image = np.random.default_rng(6).standard_normal(SHAPE)
    d = frame.forward(image)
    a = image
    for level in range(3):
        shifted = np.roll(a, -(2**level), axis=1)  # a(r, c + 2^l)
        assert np.allclose(d[level], 2.0 ** ((level - 2) / 2) * (a - shifted), atol=1e-12)
        a = 0.5 * (a + np.roll(a, 2**level, axis=1))  # the residual at p averages p with its source p - 2^l
    assert np.allclose(d[3], np.sqrt(2.0**3 / 2.0) * a, atol=1e-12)
    # in 1-D terms: a row of the low-pass is the moving mean over 2^L consecutive pixels
    assert np.allclose(a[0, 7], image[0, 0:8].mean())


@pytest.mark.parametrize(("levels", "shape"), [(1, (8, 8)), (3, (16, 8)), (5, (32, 32))])
def test_grouplet_frame_costs_l_plus_1_times_n_updates(levels, shape):
    """Section 2.2: O(N (L+1)) operations, counted (one update per pixel per scale, plus the low-pass)."""
    n = shape[0] * shape[1]
    assoc = np.random.default_rng(7).integers(0, n, size=(levels, n))
    frame = GroupletTightFrame(assoc, shape)
    image = np.random.default_rng(8).random(shape)
    d = frame.forward(image)
    assert frame.last_count == (levels + 1) * n
    frame.inverse(d)
    assert frame.last_count == (levels + 1) * n
    assert d.size == (levels + 1) * n


def test_grouplet_frame_order_is_computed_from_the_association_field():
    """Sources of each target are processed together (a counting sort by A_l), self-associations first."""
    assoc = converging(2)
    frame = GroupletTightFrame(assoc, SHAPE)
    for level in range(2):
        order = frame.orders[level]
        assert np.array_equal(np.sort(order), np.arange(N))
        targets = assoc[level][order]
        assert np.all(np.diff(targets) >= 0)
        assert np.all(order[np.searchsorted(targets, np.arange(10))] == np.arange(10))


def test_grouplet_frame_rejects_bad_input():
    with pytest.raises(ValueError):
        GroupletTightFrame(np.zeros((2, 5), dtype=int), SHAPE)
    with pytest.raises(ValueError):
        GroupletTightFrame(np.full((2, N), N), SHAPE)
    frame = GroupletTightFrame(converging(2), SHAPE)
    with pytest.raises(ValueError):
        frame.forward(np.zeros((5, 5)))
    with pytest.raises(ValueError):
        frame.inverse(np.zeros((2,) + SHAPE))


def reference_forward(image, src, dst, detail, share, low):
    """The one-image sequential scan of texsyn 0.3 (plain Python, IEEE doubles as in numba)."""
    levels, n = src.shape
    out = np.empty((levels + 1, n))
    a = image.copy()
    for lv in range(levels):
        r = a.copy()  # the residual, updated in place
        for k in range(n):
            m, p = src[lv, k], dst[lv, k]
            diff = a[m] - r[p]
            out[lv, m] = detail[lv, k] * diff
            r[p] += share[lv, k] * diff
        a = r
    out[levels] = low * a
    return out


def reference_inverse(coefficients, src, dst, detail, share, low):
    """The one-image inverse scan of texsyn 0.3 (plain Python)."""
    levels, n = src.shape
    r = coefficients[levels] / low
    for lv in range(levels - 1, -1, -1):
        source = np.empty(n)
        for k in range(n - 1, -1, -1):
            m, p = src[lv, k], dst[lv, k]
            delta = coefficients[lv, m] / detail[lv, k]  # a(m) - r(p) before the merge
            old = r[p] - share[lv, k] * delta
            source[m] = old + delta
            r[p] = old
        r = 0.5 * (r + source)
    return r


@pytest.mark.parametrize("normalized", [False, True])
def test_interleaved_blocks_give_the_bytes_of_the_one_image_scan(normalized):
    """Issue 20: the frame scans several images at once (interleaved, in blocks on numba's
    threads); every coefficient and pixel must be the bytes of the one-image reference scan,
    with the normalisation by ``scales`` done afterwards in NumPy."""
    from texsyn.transforms.grouplet_frame import _forward_block, _forward_rows, _inverse_block, _inverse_rows

    shape = (24, 20)
    n = shape[0] * shape[1]
    rng = np.random.default_rng(11)
    frame = GroupletTightFrame(rng.integers(0, n, size=(3, n)), shape)
    images = rng.standard_normal((5, n))
    scales = frame.scales if normalized else np.ones((1, 1))
    expected = np.stack([reference_forward(image, frame.orders, *frame._merges) for image in images], axis=1)
    if normalized:
        expected = expected / frame.scales[:, None]
    out = np.empty_like(expected)
    work = frame.work_buffer(5)
    _forward_block(images, frame.orders, *frame._merges, scales, normalized, out, work, 0, 5)
    assert out.tobytes() == expected.tobytes()
    threaded = np.empty_like(expected)
    _forward_rows(images, frame.orders, *frame._merges, scales, normalized, threaded, work, 3)
    assert threaded.tobytes() == expected.tobytes()
    coefficients = expected + 0.1 * rng.standard_normal(expected.shape)  # off the range too
    plain = coefficients * frame.scales[:, None] if normalized else coefficients
    reference = np.stack([reference_inverse(plain[:, b], frame.orders, *frame._merges) for b in range(5)])
    back = np.empty((5, n))
    _inverse_block(coefficients, frame.orders, *frame._merges, scales, normalized, back, work, 0, 5)
    assert back.tobytes() == reference.tobytes()
    threaded_back = np.empty((5, n))
    _inverse_rows(coefficients, frame.orders, *frame._merges, scales, normalized, threaded_back, work, 2)
    assert threaded_back.tobytes() == reference.tobytes()
