import itertools

import numpy as np
import pytest

from texsyn.ops.seams import boundary_cut_mask, cut_mask, l_shaped_cut, min_path


def all_paths(rows, cols, start_cols=None):
    """Every top-to-bottom path moving at most one column per row."""
    starts = range(cols) if start_cols is None else start_cols
    paths = [[c] for c in starts]
    for _ in range(rows - 1):
        paths = [p + [c] for p in paths for c in (p[-1] - 1, p[-1], p[-1] + 1) if 0 <= c < cols]
    return paths


@pytest.mark.parametrize("seed", range(5))
def test_vertical_cut_is_the_minimum_over_admissible_paths(seed):
    e = np.random.default_rng(seed).random((6, 4))
    path = min_path(e)
    cost = e[np.arange(6), path].sum()
    best = min(e[np.arange(6), p].sum() for p in all_paths(6, 4))
    assert np.isclose(cost, best)
    assert np.all(np.abs(np.diff(path)) <= 1)


def test_vertical_and_horizontal_masks_split_along_the_path():
    e = np.random.default_rng(9).random((8, 8))
    mask = boundary_cut_mask(e, left=3, top=0)
    path = min_path(e[:, :3])
    for i in range(8):
        assert not mask[i, : path[i]].any() and mask[i, path[i] :].all()
    mask_h = boundary_cut_mask(e, left=0, top=3)
    path_h = min_path(e[:3, :].T)
    for j in range(8):
        assert not mask_h[: path_h[j], j].any() and mask_h[path_h[j] :, j].all()


@pytest.mark.parametrize("seed", range(6))
def test_l_shaped_cut_is_the_minimum_pair_of_paths(seed):
    n, o = 5, 2
    e = np.random.default_rng(seed).random((n, n))
    ci, cj, v_cols, h_rows = l_shaped_cut(e, o, o)
    cost = e[np.arange(ci, n), v_cols].sum() + e[h_rows, np.arange(cj, n)].sum() - e[ci, cj]
    best = np.inf
    for a, b in itertools.product(range(o), range(o)):
        down = min(e[np.arange(a, n), p].sum() for p in all_paths(n - a, o, [b]))
        right = min(e[p, np.arange(b, n)].sum() for p in all_paths(n - b, o, [a]))
        best = min(best, down + right - e[a, b])
    assert np.isclose(cost, best)
    mask = boundary_cut_mask(e, left=o, top=o)
    # both paths take the new patch, the corner area before them keeps the old content
    assert mask[np.arange(ci, n), v_cols].all() and mask[h_rows, np.arange(cj, n)].all()
    assert not mask[:ci, :cj].any()
    for i in range(max(ci, o), n):  # below the top strip: split by the vertical path
        assert not mask[i, : v_cols[i - ci]].any() and mask[i, v_cols[i - ci] :].all()
    for j in range(max(cj, o), n):  # right of the left strip: split by the horizontal path
        assert not mask[: h_rows[j - cj], j].any() and mask[h_rows[j - cj] :, j].all()
    assert mask[o:, o:].all()


def test_l_cut_side_without_labelling_is_the_labelled_component():
    """The L-cut's new side found from the paths alone (no scipy.ndimage at start-up) equals the
    4-connected component a labelling gives, on random cuts of every shape; the rare cut whose
    paths touch diagonally around a pixel of that side is handed to the labelling."""
    from texsyn.ops.seams import _inside_l_cut, _inside_l_cut_by_labels

    rng = np.random.default_rng(20)
    compared = 0
    for trial in range(3000):
        h, w = (int(v) for v in rng.integers(3, 30, size=2))
        left, top = int(rng.integers(1, w)), int(rng.integers(1, h))
        e = rng.random((h, w)) ** (1 + 7 * (trial % 2))
        if trial % 3 == 2:  # a cheap diagonal: both paths like to follow it
            d = np.arange(min(h, w))
            e[d, d] *= 0.01
        ci, cj, v_cols, h_rows = l_shaped_cut(e, left, top)
        fast = _inside_l_cut(h, w, ci, cj, v_cols, h_rows)
        if fast is not None:
            compared += 1
            assert np.array_equal(fast, _inside_l_cut_by_labels(h, w, ci, cj, v_cols, h_rows)), trial
    assert compared > 2900


def test_cut_on_every_side_runs_through_the_trailing_strips_along_the_least_error():
    """On a torus the last block of a row overlaps the first on its right: the cut runs
    through that strip too, along the column where old and new agree (docs/tiling.md)."""
    old, new = np.zeros((12, 12)), np.ones((12, 12))
    new[:, 9] = 0.0  # old and new agree on one column of the right strip
    known = np.zeros((12, 12), dtype=bool)
    known[:, 8:] = True
    assert cut_mask(old, new, known).all()  # the plain cut: the known right strip is overwritten
    take = cut_mask(old, new, known, every_side=True)
    assert take[:, :10].all() and not take[:, 10:].any()
    known[:, :3] = known[:3] = known[-2:] = True  # all four sides
    take = cut_mask(old, new, known, every_side=True)
    assert take[3:-2, 3:8].all() and not take[:, 10:].any() and not take[-2:].all() and not take[:3].all()


def test_blocks_on_a_torus_see_their_wrapped_neighbours():
    from texsyn.drivers.raster import fill_blocks, torus_positions

    rows, cols = torus_positions(20, 8, 6), torus_positions(26, 8, 6)
    seen = []

    def choose(block):
        seen.append(block.known.copy())
        return block.row * 100 + block.col

    canvas = np.zeros((20, 26, 1))
    done = fill_blocks(canvas, rows, cols, 8, choose, lambda block, v: np.full((8, 8, 1), v), torus=True)
    assert done.all() and len(seen) == rows.size * cols.size
    assert seen[cols.size - 1][:, -2:].all() and not seen[cols.size - 2][:, -1].any()  # right, wrapped
    assert seen[-1][:2].all() and seen[-1][-2:].all() and seen[-1][:, :2].all() and seen[-1][:, -2:].all()
    assert canvas[0, 0, 0] == rows[-1] * 100 + cols[-1]  # the last block wrapped onto the corner
