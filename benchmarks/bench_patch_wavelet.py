"""Peyré 2007 patch-valued wavelet transform: timings, the modification sequence, figures.

Usage::

    python benchmarks/bench_patch_wavelet.py [--textures DIR] [--out benchmarks/patch_wavelet.md]
    python benchmarks/bench_patch_wavelet.py --part ratio   # only the last section, rewritten in place

Measures (medians, this machine):

* synthesis 128x128 colour exemplar -> 256x256 (fit + sample, and sample alone; target 10 s);
* modification of a 256x256 texture (fit, equalisation, feature estimation, LLE of every
  width, forward and inverse transform; target 30 s) for a grey pair and a colour pair;
* the ratio sequence 0 / 0.1 / 0.5 / 1 of each pair (paper Figs. 7-8): fraction of pixels
  that keep their ratio-0 coordinate, share of kept details, and the images;
* the coarse-to-fine progression of a synthesis (Fig. 4), sigma profiles (Fig. 6) and a
  2x2 tiling of a pure synthesis (Fig. 5, periodicity);
* the modification along the ratio 0, 0.1, ..., 1 (issue 19) of Sand-01 toward Brick-00 and
  back, with the paper's per-coefficient thresholding (texsyn 0.2's ``modify``, kept as
  ``thresholding='coefficient'``) and the local thresholding that replaced it: distances to
  both textures, mean gradient, bed-joint share, and one contact sheet per pair.

Images go to ``benchmarks/results/`` (not committed: they are made of the exemplars'
pixels), except the contact sheets ``patch_wavelet_modify_strip_*.png`` (``.gitignore``); the
markdown table lists their file names.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np
from _common import machine, parser

import texsyn
from texsyn.io import read_image, write_image
from texsyn.ops import wrap_seam_ratio

SYNTHESIS_FILES = [
    "gh_tartavel_vistex/Brick-00.png",
    "gh_tartavel_vistex/Sand-01.png",
    "gh_tartavel_vistex/Fabric-13.png",
]
#: (input texture, exemplar) pairs of the modification experiment
PAIRS = [
    ("gh_lcv_textureSynth/nuts.png", "gh_lcv_textureSynth/text.png"),
    ("gh_quilting/t2.png", "gh_tartavel_vistex/Brick-00.png"),
]
RATIOS = (0.0, 0.1, 0.5, 1.0)
#: (input texture, exemplar) pairs of the modification along the ratio (128x128 crops)
RATIO_PAIRS = [
    ("gh_tartavel_vistex/Sand-01.png", "gh_tartavel_vistex/Brick-00.png"),
    ("gh_tartavel_vistex/Brick-00.png", "gh_tartavel_vistex/Sand-01.png"),
]
PATH = tuple(round(0.1 * i, 1) for i in range(11))
RATIO_SECTION = "## Modification along the ratio (issue 19)"


def square(image: np.ndarray, size: int) -> np.ndarray:
    """Top-left ``size x size`` crop, tiled symmetrically when the image is smaller."""
    h, w = image.shape[:2]
    pad = ((0, max(0, size - h)), (0, max(0, size - w))) + ((0, 0),) * (image.ndim - 2)
    return np.pad(image, pad, mode="symmetric")[:size, :size]


def bed_joint_share(image: np.ndarray) -> float:
    """Share of the (grey) variance carried by the row means: the bed joints of a wall that
    cross the whole width make it large, broken joints small."""
    x = np.asarray(image, dtype=np.float64)
    x = x.mean(axis=2) if x.ndim == 3 else x
    return float(np.var(x.mean(axis=1)) / np.var(x))


def path_summary(values: np.ndarray) -> str:
    """Path length (sum of steps over the net change: 1 when monotone) and largest step."""
    net = abs(values[-1] - values[0])
    steps = np.abs(np.diff(values))
    return f"path {steps.sum() / net:.2f}, largest step {steps.max() / net:.2f}"


def ratio_section(args) -> list[str]:
    """Modification along the ratio, per-coefficient (before) and local (after) thresholding."""
    from texsyn.metrics import mean_gradient, ps_distance

    lines = [
        RATIO_SECTION,
        "",
        "Ratios 0, 0.1, ..., 1, 128x128 crops, colour, equalisation on (the defaults). *Before*:",
        "the paper's per-coefficient rule, texsyn 0.2's `modify` (`thresholding='coefficient'`,",
        "byte for byte the old output); *after*: local thresholding (the default). ps: `ps_distance`",
        "to the exemplar and to the input; grad: `mean_gradient`; beds: share of the variance",
        "carried by the row means (continuous bed joints); kept: share of pixels keeping their",
        "ratio-0 exemplar position. Path: sum of the steps over the net change (1 = monotone);",
        "largest step: over the net change (0.1 for an even transition).",
        "",
    ]
    for input_name, exemplar_name in RATIO_PAIRS:
        texture = square(read_image(args.textures / input_name), 128)
        ex = read_image(args.textures / exemplar_name)[:128, :128]
        a, b = Path(input_name).stem, Path(exemplar_name).stem
        method = texsyn.make_method("patch_wavelet").fit(ex)
        runs, rows = {}, {}
        for label, thresholding in (("before", "coefficient"), ("after", "local")):
            t0 = time.perf_counter()
            results = method.modify(texture, list(PATH), thresholding=thresholding)
            seconds = time.perf_counter() - t0
            base = results[0].source_map
            stats = np.array(
                [
                    (
                        ps_distance(r.image, ex),
                        ps_distance(r.image, texture),
                        mean_gradient(r.image),
                        bed_joint_share(r.image),
                        np.mean(np.all(r.source_map == base, axis=-1)),
                    )
                    for r in results
                ]
            )
            runs[label] = results
            rows[label] = (stats, seconds)
        strip = np.concatenate(
            [np.concatenate([r.image for r in runs[label]], axis=1) for label in ("before", "after")], axis=0
        )
        sheet = f"patch_wavelet_modify_strip_{a}_{b}.png"
        write_image(args.images / sheet, strip)
        lines += [
            f"### {a} (input) toward {b} (exemplar)",
            "",
            f"![{a} toward {b}, ratios 0 to 1; top: before, bottom: after](results/{sheet})",
            "",
            "| ratio | ps exemplar (before / after) | ps input | grad | beds | kept |",
            "|---:|---:|---:|---:|---:|---:|",
        ]
        before, after = rows["before"][0], rows["after"][0]
        for i, ratio in enumerate(PATH):
            cells = [f"{before[i, k]:.3f} / {after[i, k]:.3f}" for k in range(5)]
            lines.append(f"| {ratio:g} | " + " | ".join(cells) + " |")
        lines += [
            "",
            f"ps to the exemplar: before {path_summary(before[:, 0])}; after {path_summary(after[:, 0])}.",
            f"ps to the input: before {path_summary(before[:, 1])}; after {path_summary(after[:, 1])}.",
            f"Time for the 11 ratios (one analysis): before {rows['before'][1]:.1f} s, after {rows['after'][1]:.1f} s.",
            "",
        ]
        print("\n".join(lines[-14:]), flush=True)
    return lines


def main(argv: list[str] | None = None) -> int:
    cli = parser(__doc__.splitlines()[0], "patch_wavelet.md", repeats=3)
    cli.add_argument("--part", choices=["all", "ratio"], default="all", help="'ratio': only the last section")
    args = cli.parse_args(argv)
    args.images.mkdir(parents=True, exist_ok=True)
    if args.part == "ratio":
        text = args.out.read_text() if args.out.exists() else ""
        head = text.split(RATIO_SECTION)[0].rstrip("\n")
        args.out.write_text(head + "\n\n" + "\n".join(ratio_section(args)) + "\n")
        print(f"wrote {args.out}")
        return 0
    lines = [
        "# Patch-valued wavelet transform (Peyré 2007)",
        "",
        machine() + " Default parameters.",
        "",
    ]

    # warm-up (numba compilation, lazy imports)
    warm = read_image(args.textures / SYNTHESIS_FILES[0])[:40, :40]
    texsyn.make_method("patch_wavelet", sigma=0.1).fit(warm).sample((32, 32), rng=0)

    # ------------------------------------------------------------------ synthesis timings
    lines += [
        "## Synthesis, 128x128 colour exemplar -> 256x256 (target 10 s)",
        "",
        "| exemplar | fit (s) | sample (s) | fit + sample (s) | seam ratio of the 2x2 tiling |",
        "|---|---:|---:|---:|---:|",
    ]
    totals = []
    for name in SYNTHESIS_FILES:
        ex = read_image(args.textures / name)[:128, :128]
        fits, samples = [], []
        for seed in range(args.repeats):
            t0 = time.perf_counter()
            method = texsyn.make_method("patch_wavelet").fit(ex)
            t1 = time.perf_counter()
            image = method.sample((256, 256), rng=seed)
            t2 = time.perf_counter()
            fits.append(t1 - t0)
            samples.append(t2 - t1)
        total = statistics.median(f + s for f, s in zip(fits, samples))
        totals.append(total)
        stem = Path(name).stem
        write_image(args.images / f"patch_wavelet_synthesis_{stem}_tiled.png", np.tile(image, (2, 2, 1)))
        lines.append(
            f"| {stem} | {statistics.median(fits):.2f} | {statistics.median(samples):.2f} | {total:.2f} | {wrap_seam_ratio(image):.2f} |"
        )
        print(lines[-1], flush=True)
    lines += ["", f"Median fit + sample: **{statistics.median(totals):.2f} s** (target 10 s).", ""]

    # ------------------------------------------------------------------ figures 4 and 6
    ex = read_image(args.textures / SYNTHESIS_FILES[0])[:128, :128]
    frames = []
    method = texsyn.make_method("patch_wavelet").fit(ex)
    pure = method.sample((256, 256), rng=7, callback=lambda p: frames.append(p.image))
    strip = [np.kron(f, np.ones((256 // f.shape[0], 256 // f.shape[1], 1))) for f in frames]
    write_image(args.images / "patch_wavelet_progression.png", np.concatenate(strip, axis=1))
    profiles = {
        "none": (0.0,),
        "fine": (0.3, 0.3, 0.3),
        "coarse": (0, 0, 0, 0.3, 0.3, 0.3, 0.3),
        "all": (0.2,),
    }
    lines += [
        "## Sigma profiles (Fig. 6), same seed as the pure synthesis",
        "",
        "| profile (finest level first) | pixels differing from the pure synthesis | image |",
        "|---|---:|---|",
    ]
    for label, sigma in profiles.items():
        image = texsyn.make_method("patch_wavelet", sigma=sigma).fit(ex).sample((256, 256), rng=7)
        path = f"patch_wavelet_sigma_{label}.png"
        write_image(args.images / path, image)
        diff = np.mean(np.any(image != pure, axis=-1))
        lines.append(f"| {label}: {','.join(f'{s:g}' for s in sigma)} | {diff:.3f} | {path} |")
        print(lines[-1], flush=True)
    lines += [
        "",
        "Progression (Fig. 4): patch_wavelet_progression.png (2x2 up to 256x256, nearest-neighbour enlarged).",
        "",
    ]

    # ------------------------------------------------------------------ modification
    lines += ["## Modification of a 256x256 texture (target 30 s, LLE included)", ""]
    for input_name, exemplar_name in PAIRS:
        texture = square(read_image(args.textures / input_name), 256)
        ex = read_image(args.textures / exemplar_name)
        ex = ex[:128, :128]
        t0 = time.perf_counter()
        method = texsyn.make_method("patch_wavelet").fit(ex)
        method.modify(texture, 0.1)
        t1 = time.perf_counter()
        results = method.modify(texture, list(RATIOS))
        t2 = time.perf_counter()
        a, b = Path(input_name).stem, Path(exemplar_name).stem
        lines += [
            f"### {a} (input, {texture.shape[1]}x{texture.shape[0]}) with the features of {b} (exemplar, 128x128)",
            "",
            f"One modification (fit + equalisation + features + LLE + forward + inverse): **{t1 - t0:.1f} s**; "
            f"the four ratios sharing one analysis: {t2 - t1:.1f} s.",
            "",
            "| ratio | pixels keeping their ratio-0 coordinate | details kept | image | magnitudes |",
            "|---:|---:|---:|---|---|",
        ]
        base = results[0].source_map
        n_details = np.count_nonzero(results[0].magnitudes)
        write_image(args.images / f"patch_wavelet_modify_{a}_input.png", texture)
        for r in results:
            frac = np.mean(np.all(r.source_map == base, axis=-1))
            kept = np.count_nonzero(r.magnitudes) / max(n_details, 1)
            img = f"patch_wavelet_modify_{a}_{b}_{r.ratio:g}.png"
            mag = f"patch_wavelet_modify_{a}_{b}_{r.ratio:g}_magnitudes.png"
            write_image(args.images / img, r.image)
            top = results[0].magnitudes.max()
            write_image(args.images / mag, np.sqrt(r.magnitudes / top))
            lines.append(f"| {r.ratio:g} | {frac:.3f} | {kept:.3f} | {img} | {mag} |")
            print(lines[-1], flush=True)
        lines.append("")
    lines += ratio_section(args)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
