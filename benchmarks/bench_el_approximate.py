"""Efros–Leung's approximate search against the exact one (``docs/methods/efros_leung.md``).

Usage::

    python benchmarks/bench_el_approximate.py [--size 256] [--files Brick-00.png ...]

For each exemplar (top-left 128x128 crop; ``grey`` = BT.601 luma of the first), an
approximate growth (``search='approximate'``) is run pixel by pixel, and before every pixel
the exact distances of its window to every exemplar window are computed: the search error
is measured on the approximate run's own states. Per pixel it reports whether the chosen
window would be a candidate of the exact rule (distance within ``(1 + tolerance)`` of the
exact best), and the excess of its distance over the exact best. The outputs of both
searches are compared with ``texsyn.metrics.ps_distance``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import texsyn
from texsyn.io import read_image
from texsyn.metrics import ps_distance
from texsyn.ops.kcoherence import CoherentWindows
from texsyn.ops.nonparametric import NonParametricSampler


def search_error(
    exemplar: np.ndarray, shape: tuple[int, int], *, k: int = 4, tolerance: float = 0.1, seed: int = 0
):
    """Per accepted pixel of an approximate growth: (chosen exact distance, exact best), per unit weight."""
    from texsyn.drivers.raster import grow_pixels
    from texsyn.ops.linalg import fixed_order

    exact = NonParametricSampler(exemplar, 11)
    records: list[tuple[float, float]] = []

    class Measured(CoherentWindows):
        def grow_pass(
            self, rows, cols, uniforms, values, filled, source, tolerance, accept, stamp, first_stamp
        ):
            chosen = np.full(rows.size, -1, dtype=np.int64)
            w = self.window
            for i in range(rows.size):
                win = values[rows[i] : rows[i] + w, cols[i] : cols[i] + w]
                known = filled[rows[i] : rows[i] + w, cols[i] : cols[i] + w]
                weights = known * self.gauss
                full = np.broadcast_to(weights[..., None], win.shape)
                d = exact.bank.distances(win.reshape(1, -1), full.reshape(1, -1))[0] / weights.sum()
                one = slice(i, i + 1)
                chosen[i] = super().grow_pass(
                    rows[one],
                    cols[one],
                    uniforms[one],
                    values,
                    filled,
                    source,
                    tolerance,
                    accept,
                    stamp,
                    first_stamp + i,
                )[0]
                if chosen[i] >= 0:
                    records.append((d[chosen[i]], d.min()))
            return chosen

    sampler = Measured(exemplar, 11, k=k)
    with fixed_order():
        values, _ = grow_pixels(sampler, shape, tolerance=tolerance, rng=np.random.default_rng(seed))
    return np.array(records), values


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--textures", default="/work/shared/textures/gh_tartavel_vistex")
    p.add_argument("--files", nargs="*", default=["Brick-00.png", "Sand-01.png", "Fabric-13.png"])
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--k", type=int, default=4)
    args = p.parse_args()
    print(
        "| exemplar | pixels | chosen is an exact candidate | mean best | mean excess | p90 excess | PS exact | PS approx |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    cases = []
    for i, name in enumerate(args.files):
        ex = read_image(Path(args.textures) / name).astype(np.float64)[:128, :128]
        cases.append((Path(name).stem, ex))
        if i == 0:
            cases.append((Path(name).stem + " grey", ex @ np.array([0.299, 0.587, 0.114])))
    for label, ex in cases:
        t = time.perf_counter()
        rec, approx = search_error(ex, (args.size, args.size), k=args.k)
        chosen, best = rec[:, 0], rec[:, 1]
        inside = chosen <= best * 1.1 + 1e-10
        excess = chosen - best
        exact_out = texsyn.synthesize(ex, "efros_leung", (args.size, args.size), rng=0)
        fast_out = texsyn.synthesize(
            ex, "efros_leung", (args.size, args.size), rng=0, search="approximate", k_coherence=args.k
        )
        ref = ex.astype(np.float32)
        print(
            f"| {label} | {len(rec)} | {inside.mean():.1%} | {best.mean():.2e} | {excess.mean():.2e} "
            f"| {np.percentile(excess, 90):.2e} "
            f"| {ps_distance(exact_out, ref):.3f} | {ps_distance(fast_out, ref):.3f} |",
            flush=True,
        )
        del approx
        print(f"  ({time.perf_counter() - t:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
