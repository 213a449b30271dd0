"""Constrained sparse synthesis: the paper's step-by-step study (Fig. 4) and where time goes.

Usage::

    python benchmarks/bench_sparse.py [--textures DIR] [--files F ...] [--out benchmarks/sparse.md]

For each exemplar (top-left 128x128 colour crop) the dictionaries are learned once (mode
'full', timed per stage), then every mode of :data:`texsyn.methods.sparse.MODES` synthesises
256x256 with seed 0 from the same fitted state, plus two variants of 'full': 'full-mean'
(the constant low-pass reference and no convergence test of texsyn 0.2,
``lowpass_ref='mean', tolerance=0``) and 'full-1scale' (one scale, for the multiscale gain).
Measured per run:

* smooth patches: share of the output's 12x12 patches whose variance is below the 10th
  percentile of the exemplar's patch variances (10 % for the exemplar itself);
* gradient ratio: mean squared gradient of the output over the exemplar's (1 = as sharp);
* local-mean spread: std of the 12x12 box-filtered output over that of the exemplar
  (issue 19 asks for 0.9-1.1);
* ridges: share of the output's energy at the zeros of the 12x12 box filter (frequencies
  below 0.3), over the exemplar's (128x128 tiles);
* PS distance: :func:`texsyn.metrics.ps_distance` to the exemplar (lower is better);
* outer iterations per scale (coarsest first) and whether every scale converged;
* time of ``sample`` split into coding (constrained matching pursuit), reconstruction
  (averaging or graph cuts) and image update (gradient steps).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import texsyn
from texsyn.io import read_image
from texsyn.methods.sparse import MODES
from texsyn.metrics import box_null_energy_share, local_mean_spread, ps_distance
from texsyn.ops import extract_patches

REPO = Path(__file__).resolve().parents[1]
DEFAULT_TEXTURES = REPO.parent / "shared" / "textures"
DEFAULT_FILES = [
    "gh_tartavel_vistex/Brick-00.png",
    "gh_tartavel_vistex/Fabric-13.png",
    "gh_tartavel_vistex/Tile-04.png",
    "gh_quilting/t4.png",
    "gh_tartavel_vistex/Stone-02.png",
    "gh_tartavel_vistex/Sand-01.png",
]


def patch_variances(image: np.ndarray, tau: int) -> np.ndarray:
    patches, _ = extract_patches(image, tau, stride=2)
    return patches.var(axis=1)


def gradient_energy(image: np.ndarray) -> float:
    x = np.asarray(image, dtype=np.float64)
    gy = np.diff(x, axis=0)[:, :-1]
    gx = np.diff(x, axis=1)[:-1, :]
    return float(np.mean(gx**2 + gy**2))


def lowpass_std(image: np.ndarray, tau: int) -> float:
    return local_mean_spread(image, tau)


null_band_share = box_null_energy_share


def ridge_ratio(image: np.ndarray, exemplar: np.ndarray, tau: int) -> float:
    side = exemplar.shape[0]
    tiles = [image[i : i + side, j : j + side] for i in range(0, image.shape[0] - side + 1, side)
             for j in range(0, image.shape[1] - side + 1, side)]  # fmt: skip
    return float(np.mean([null_band_share(t, tau) for t in tiles]) / null_band_share(exemplar, tau))


#: the runs of every exemplar: (label, sampling parameters changed on the loaded model)
RUNS = [(m, {"mode": m}) for m in MODES] + [
    ("full-mean", {"mode": "full", "lowpass_ref": "mean", "tolerance": 0.0}),
    ("full-1scale", {"mode": "full", "n_scales": 1}),
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    parser.add_argument("--files", nargs="*", default=DEFAULT_FILES)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "sparse.md")
    args = parser.parse_args(argv)

    rows, fit_rows, stage_rows = [], [], []
    per_mode: dict[str, dict[str, list[float]]] = {label: {} for label, _ in RUNS}
    for name in args.files:
        ex = read_image(args.textures / name)[:128, :128].astype(np.float64)
        start = time.perf_counter()
        fitted = texsyn.make_method("sparse").fit(ex)
        fit_total = time.perf_counter() - start
        fit_rows.append(
            f"| {name} | {fit_total:.1f} | {fitted.fit_seconds_['dictionary']:.1f} | {fitted.fit_seconds_['exemplar_codes']:.1f} |"
        )
        saved = texsyn.save(fitted, Path(tempfile.mkdtemp()) / "sparse.npz")
        tau = fitted.patch_size
        threshold = np.percentile(patch_variances(ex, tau), 10)
        ge_ex, lp_ex = gradient_energy(ex), lowpass_std(ex, 12)
        for mode, changes in RUNS:
            sampling = {k: v for k, v in changes.items() if k != "n_scales"}
            method = texsyn.load(saved, **sampling)
            if "n_scales" in changes:  # a learned parameter: sample the finest scale only
                method.n_scales = changes["n_scales"]
            log = []
            start = time.perf_counter()
            result = method.sample_with_map((256, 256), rng=0, callback=log.append)
            seconds = time.perf_counter() - start
            out = np.asarray(result.image, dtype=np.float64)
            stages = log[-1].info["seconds"] if log else {}
            diag = result.diagnostics
            values = {
                "smooth": float(np.mean(patch_variances(out, tau) < threshold)),
                "gradient": gradient_energy(out) / ge_ex,
                "drift": lowpass_std(out, 12) / lp_ex,
                "ridges": ridge_ratio(out, ex, 12),
                "ps": ps_distance(out, ex),
                "seconds": seconds,
            }
            for k, v in values.items():
                per_mode[mode].setdefault(k, []).append(v)
            iterations = "/".join(str(i) for i in diag["iterations"])
            converged = "yes" if diag["converged"].all() else "no"
            rows.append(
                f"| {name} | {mode} | {values['smooth']:.3f} | {values['gradient']:.3f} | {values['drift']:.3f} | "
                f"{values['ridges']:.2f} | {values['ps']:.3f} | {iterations} | {converged} | {seconds:.1f} |"
            )
            stage_rows.append(
                f"| {name} | {mode} | {stages.get('coding', 0):.1f} | {stages.get('reconstruction', 0):.1f} | {stages.get('image_update', 0):.1f} | {seconds:.1f} |"
            )
            print(rows[-1], flush=True)
    summary = [
        f"| {mode} | {statistics.median(v['smooth']):.3f} | {statistics.median(v['gradient']):.3f} | "
        f"{statistics.median(v['drift']):.3f} | {statistics.median(v['ridges']):.2f} | "
        f"{statistics.median(v['ps']):.3f} | {statistics.median(v['seconds']):.1f} |"
        for mode, v in per_mode.items()
    ]
    lines = [
        "# Constrained sparse synthesis: ablation (Tartavel et al. 2013, Fig. 4) and timings",
        "",
        "128x128 colour exemplars (top-left crops) synthesised to 256x256, seed 0, default parameters; "
        "the dictionaries are learned once per exemplar (mode 'full') and shared by every mode.",
        "Smooth patches: share of output 12x12 patches with variance below the exemplar's 10th percentile. "
        "Gradient: mean squared gradient, output / exemplar. Spread: std of the 12x12 box-filtered image, "
        "output / exemplar (issue 19: within 0.9-1.1). Ridges: energy share at the zeros of the 12x12 box "
        "filter, output / exemplar. PS: Portilla-Simoncelli statistics distance to the exemplar. "
        "'full-mean' is texsyn 0.2's full mode (constant low-pass reference, 30 iterations per scale); "
        "'full-1scale' is the full mode on the finest scale only.",
        "",
        "## Medians over exemplars",
        "",
        "| mode | smooth patches | gradient ratio | local-mean spread | ridges | PS distance | sample (s) |",
        "|---|---:|---:|---:|---:|---:|---:|",
        *summary,
        "",
        "## Per exemplar",
        "",
        "| exemplar | mode | smooth patches | gradient ratio | local-mean spread | ridges | PS distance | iterations | converged | sample (s) |",
        "|---|---|---:|---:|---:|---:|---:|---|---|---:|",
        *rows,
        "",
        "## Where the time goes",
        "",
        "Fit (seconds): total, K-SVD dictionary learning (all scales), exemplar codes (usage counts).",
        "",
        "| exemplar | fit | dictionary | exemplar codes |",
        "|---|---:|---:|---:|",
        *fit_rows,
        "",
        "Sample (seconds): coding (constrained matching pursuit), reconstruction, image update, total.",
        "",
        "| exemplar | mode | coding | reconstruction | image update | total |",
        "|---|---|---:|---:|---:|---:|",
        *stage_rows,
    ]
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
