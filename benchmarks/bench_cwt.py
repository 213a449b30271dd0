"""DT-CWT sampling (Gallagher and Kokaram): continuity across blocks, before and after issue 19.

Usage::

    # once with the old code importable (records its figures and images), then with the new
    python benchmarks/bench_cwt.py run --label before [--variants plain,refine]
    python benchmarks/bench_cwt.py run --label after
    python benchmarks/bench_cwt.py report [--out benchmarks/cwt.md]

``run`` synthesises, for each exemplar of :data:`EXEMPLARS` (its top-left 128x128 crop, or
the whole image when smaller), a 256x256 texture with seed 0 for each variant of
:data:`VARIANTS` (default parameters, ``refine=False`` and ``refine=True``), and stores the
figures in ``benchmarks/results/cwt_<label>.json`` and the images beside it (not
committed). Measured per run:

* ``ps``: :func:`texsyn.metrics.ps_distance` to the exemplar (lower is better);
* ``coherent``: share of neighbouring output pixels whose sources are neighbours in the
  exemplar (right neighbour's source = source + (0, 1), bottom's = source + (1, 0));
* ``border``: the same share over the pixel pairs that straddle a border of the coarsest
  level's ``2^L x 2^L`` blocks, outside the exemplar-sized square at the centre (the seed):
  where neighbouring blocks continue each other instead of coming from unrelated places;
* ``seam``: mean over neighbouring pixel pairs of the squared luma difference between what
  one pixel's source continues into and what its neighbour shows (both ways), x 1e4: 0 for
  pairs copied together, large where a structure breaks across a seam;
* ``sharpness`` and ``contrast``: :func:`texsyn.metrics.sharpness_ratio` and
  :func:`texsyn.metrics.contrast_ratio` (1 = as the exemplar);
* ``time``: seconds of ``fit`` + ``sample``.

``report`` writes the table of both labels and the contact sheets
``benchmarks/results/cwt_structured.jpg`` and ``cwt_stochastic.jpg`` (exemplar, then
before plain / before refine / after plain / after refine).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from _common import DEFAULT_TEXTURES, REPO, RESULTS, machine

import texsyn
from texsyn.io import read_image, write_image
from texsyn.metrics import contrast_ratio, ps_distance, sharpness_ratio, source_seam_cost

#: name -> (file under the shared textures, kind)
EXEMPLARS = {
    "Brick-00": ("gh_tartavel_vistex/Brick-00.png", "structured"),
    "Brick-02": ("gh_tartavel_vistex/Brick-02.png", "structured"),
    "text": ("gh_lcv_textureSynth/text.png", "structured"),
    "Tile-04": ("gh_tartavel_vistex/Tile-04.png", "structured"),
    "woven (t2)": ("gh_quilting/t2.png", "structured"),
    "red brick (color_4)": ("gh_efros_leung/color_4.png", "structured"),
    "Sand-01": ("gh_tartavel_vistex/Sand-01.png", "stochastic"),
    "metal": ("gh_lcv_textureSynth/metal.png", "stochastic"),
    "Clouds-01": ("gh_tartavel_vistex/Clouds-01.png", "stochastic"),
}
#: variant -> parameters of ``cwt``
VARIANTS = {"plain": {}, "refine": {"refine": True}}
SHAPE = (256, 256)


def coherent_share(source: np.ndarray) -> float:
    """Share of right and bottom neighbour pairs whose sources are the same neighbours."""
    s = np.asarray(source, dtype=np.int64)
    right = np.all(s[:, 1:] - s[:, :-1] == (0, 1), axis=-1)
    down = np.all(s[1:, :] - s[:-1, :] == (1, 0), axis=-1)
    return 0.5 * float(right.mean() + down.mean())


def border_share(source: np.ndarray, block: int, seed: tuple[int, int]) -> float:
    """:func:`coherent_share` over the pixel pairs across the ``block`` grid, outside the
    centred ``seed``-sized square."""
    s = np.asarray(source, dtype=np.int64)
    h, w = s.shape[:2]
    top, left = (h - seed[0]) // 2, (w - seed[1]) // 2
    inside = np.zeros((h, w), dtype=bool)
    inside[top : top + seed[0], left : left + seed[1]] = True
    cols = np.arange(block, w, block)
    rows = np.arange(block, h, block)
    right = np.all(s[:, cols] - s[:, cols - 1] == (0, 1), axis=-1)
    right_out = ~(inside[:, cols] & inside[:, cols - 1])
    down = np.all(s[rows, :] - s[rows - 1, :] == (1, 0), axis=-1)
    down_out = ~(inside[rows, :] & inside[rows - 1, :])
    return float((right[right_out].sum() + down[down_out].sum()) / (right_out.sum() + down_out.sum()))


def seam_cost(source: np.ndarray, exemplar: np.ndarray) -> float:
    """The ``seam`` figure: :func:`texsyn.metrics.source_seam_cost` x 1e4."""
    return 1e4 * source_seam_cost(source, exemplar)


def load(textures: Path, file: str) -> np.ndarray:
    return read_image(textures / file)[:128, :128]


def run(label: str, textures: Path, variants: list[str]) -> None:
    folder = RESULTS / f"cwt_{label}"
    folder.mkdir(parents=True, exist_ok=True)
    texsyn.synthesize(load(textures, EXEMPLARS["metal"][0])[:64, :64], "cwt", (64, 64), rng=0)  # warm-up
    figures = {}
    for key, (file, _) in EXEMPLARS.items():
        exemplar = load(textures, file)
        for variant in variants:
            start = time.perf_counter()
            method = texsyn.make_method("cwt", **VARIANTS[variant]).fit(exemplar)
            result = method.sample_with_map(SHAPE, rng=0)
            elapsed = time.perf_counter() - start
            seed = tuple(
                min(s, (e // 2**method.levels) * 2**method.levels) for s, e in zip(SHAPE, exemplar.shape)
            )
            figures[f"{key}|{variant}"] = {
                "ps": ps_distance(result.image, exemplar),
                "coherent": coherent_share(result.source_map),
                "border": border_share(result.source_map, 2**method.levels, seed),
                "seam": seam_cost(result.source_map, exemplar),
                "sharpness": sharpness_ratio(result.image, exemplar),
                "contrast": contrast_ratio(result.image, exemplar),
                "time": elapsed,
            }
            np.save(folder / f"{key}_{variant}.npy", result.image)
            print(key, variant, {k: round(v, 4) for k, v in figures[f"{key}|{variant}"].items()}, flush=True)
    (RESULTS / f"cwt_{label}.json").write_text(json.dumps(figures, indent=1))


def sheet(keys: list[str], textures: Path, out: Path) -> None:
    rows = []
    for key in keys:
        exemplar = load(textures, EXEMPLARS[key][0])
        tiles = [exemplar]
        for label in ("before", "after"):
            for variant in VARIANTS:
                tiles.append(np.load(RESULTS / f"cwt_{label}" / f"{key}_{variant}.npy"))
        tiles = [np.repeat(t[..., None], 3, axis=2) if t.ndim == 2 else t for t in tiles]
        canvas = np.ones((SHAPE[0], len(tiles) * (SHAPE[1] + 4), 3), np.float32)
        for i, t in enumerate(tiles):
            canvas[: t.shape[0], i * (SHAPE[1] + 4) : i * (SHAPE[1] + 4) + t.shape[1]] = t
        rows.append(np.pad(canvas, ((0, 4), (0, 0), (0, 0)), constant_values=1.0))
    write_image(out, np.concatenate(rows, axis=0))


def zoom(keys: list[str], out: Path) -> None:
    """The top-right quarter of each output (half the seed, half new texture), twice enlarged:
    before plain / before refine / after plain / after refine."""
    rows = []
    for key in keys:
        tiles = []
        for label in ("before", "after"):
            for variant in VARIANTS:
                t = np.load(RESULTS / f"cwt_{label}" / f"{key}_{variant}.npy")[:128, 128:256]
                t = np.repeat(t[..., None], 3, axis=2) if t.ndim == 2 else t
                tiles.append(
                    np.pad(np.kron(t, np.ones((2, 2, 1))), ((0, 4), (0, 4), (0, 0)), constant_values=1.0)
                )
        rows.append(np.concatenate(tiles, axis=1))
    write_image(out, np.concatenate(rows, axis=0).astype(np.float32))


def report(textures: Path, out: Path) -> None:
    before = json.loads((RESULTS / "cwt_before.json").read_text())
    after = json.loads((RESULTS / "cwt_after.json").read_text())
    lines = [
        "# `cwt`: continuity across blocks, before and after (issue 19, item 3)",
        "",
        machine() + " 128x128 top-left crop (the whole image when smaller) to 256x256, seed 0, "
        "default parameters (`levels=3`, `window=5`) with `refine` False and True. Figures: "
        "`before / after`; `ps` = `ps_distance` (lower is better), `coherent` = share of "
        "neighbouring pixels whose sources are neighbours, `border` = the same share across the "
        "borders of the 8x8 blocks outside the central seed, `seam` = mismatch of the sources' "
        "continuations across neighbouring pixels (x 1e4, lower is better), `sharp` and `contrast` = ratios to "
        "the exemplar, `time` = fit + sample (s). Produced by `benchmarks/bench_cwt.py`.",
        "",
        "| exemplar | kind | refine | ps | coherent | border | seam | sharp | contrast | time |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for key, (_, kind) in EXEMPLARS.items():
        for variant in VARIANTS:
            b, a = before[f"{key}|{variant}"], after[f"{key}|{variant}"]
            cells = [
                f"{b[m]:.{d}f} / {a[m]:.{d}f}"
                for m, d in (
                    ("ps", 4),
                    ("coherent", 3),
                    ("border", 3),
                    ("seam", 2),
                    ("sharpness", 2),
                    ("contrast", 2),
                    ("time", 2),
                )
            ]
            lines.append(f"| {key} | {kind} | {variant == 'refine'} | " + " | ".join(cells) + " |")
    lines.append("")
    for kind in ("structured", "stochastic"):
        keys = [k for k, (_, c) in EXEMPLARS.items() if c == kind]
        for variant in VARIANTS:
            means = {
                m: [np.mean([f[f"{k}|{variant}"][m] for k in keys]) for f in (before, after)]
                for m in ("ps", "border", "seam")
            }
            lines.append(
                f"- {kind}, refine {variant == 'refine'}: mean ps {means['ps'][0]:.4f} -> {means['ps'][1]:.4f}, "
                f"border {means['border'][0]:.3f} -> {means['border'][1]:.3f}, "
                f"seam {means['seam'][0]:.2f} -> {means['seam'][1]:.2f}"
            )
    lines.append("")
    for kind in ("structured", "stochastic"):
        keys = [k for k, (_, c) in EXEMPLARS.items() if c == kind]
        sheet(keys, textures, RESULTS / f"cwt_{kind}.jpg")
        lines.append(
            f"Contact sheet `benchmarks/results/cwt_{kind}.jpg`: exemplar, before (refine False, "
            "True), after (refine False, True)."
        )
    zoom(["Brick-00", "Brick-02", "text"], RESULTS / "cwt_zoom.jpg")
    lines.append(
        "Zoom `benchmarks/results/cwt_zoom.jpg`: the top-right quarter of the outputs of Brick-00, "
        "Brick-02 and text (half seed, half new texture), twice enlarged, in the same order."
    )
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("command", choices=("run", "report"))
    p.add_argument("--label", default="after")
    p.add_argument("--variants", default=",".join(VARIANTS))
    p.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "cwt.md")
    args = p.parse_args(argv)
    if args.command == "run":
        run(args.label, args.textures, args.variants.split(","))
    else:
        report(args.textures, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
