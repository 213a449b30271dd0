"""Contact sheets of two versions of texsyn side by side (issue 19: "before and after").

Usage::

    # with each version importable in turn (e.g. PYTHONPATH=/path/to/old/src for the old one)
    python benchmarks/before_after.py render --out /tmp/before
    python benchmarks/before_after.py render --out /tmp/after
    python benchmarks/before_after.py sheet --before /tmp/before --after /tmp/after

``render`` synthesises, for each exemplar of ``EXEMPLARS`` (its top-left 128x128 crop) and
each method of ``METHODS``, a 256x256 texture with seed 0 and default parameters, and saves
them as ``.npy`` files. ``sheet`` writes ``benchmarks/results/before_after_<exemplar>.jpg``:
the exemplar, then one row per version (the methods in order), and prints the sharpness and
contrast ratios and ``ps_distance`` of both versions.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from _common import DEFAULT_TEXTURES, RESULTS

EXEMPLARS = {
    "brick": "gh_tartavel_vistex/Brick-00.png",
    "herringbone": "gh_tartavel_vistex/Fabric-02.png",
    "sand": "gh_tartavel_vistex/Sand-01.png",
    "stone": "gh_tartavel_vistex/Stone-02.png",
    "straw": "gh_tartavel_vistex/Fabric-13.png",
}
METHODS = ["lg", "clg", "rclg", "mslg", "portilla_simoncelli", "sparse", "cwt"]


def render(out: Path, textures: Path) -> None:
    import texsyn
    from texsyn.io import read_image

    out.mkdir(parents=True, exist_ok=True)
    for key, file in EXEMPLARS.items():
        exemplar = read_image(textures / file)[:128, :128]
        for name in METHODS:
            image = texsyn.synthesize(exemplar, name, (256, 256), rng=0)
            np.save(out / f"{key}_{name}.npy", image)
            print(key, name, flush=True)


def sheet(before: Path, after: Path, textures: Path) -> None:
    from texsyn.io import read_image, write_image
    from texsyn.metrics import contrast_ratio, ps_distance, sharpness_ratio

    RESULTS.mkdir(parents=True, exist_ok=True)
    print(
        "| exemplar | method | sharpness before / after | contrast before / after | ps_distance before / after |"
    )
    print("|---|---|---|---|---|")
    for key, file in EXEMPLARS.items():
        exemplar = read_image(textures / file)[:128, :128]
        rows = []
        for folder in (before, after):
            images = [np.load(folder / f"{key}_{name}.npy") for name in METHODS]
            rows.append(
                np.concatenate(
                    [np.pad(i, ((0, 4), (0, 4), (0, 0)), constant_values=1.0) for i in images], axis=1
                )
            )
        for name in METHODS:
            old, new = (np.load(folder / f"{key}_{name}.npy") for folder in (before, after))
            print(
                f"| {key} | {name} | {sharpness_ratio(old, exemplar):.2f} / {sharpness_ratio(new, exemplar):.2f} | "
                f"{contrast_ratio(old, exemplar):.2f} / {contrast_ratio(new, exemplar):.2f} | "
                f"{ps_distance(old, exemplar):.3f} / {ps_distance(new, exemplar):.3f} |",
                flush=True,
            )
        head = np.ones((132, rows[0].shape[1], 3), np.float32)
        head[:128, :128] = exemplar
        write_image(RESULTS / f"before_after_{key}.jpg", np.concatenate([head] + rows, axis=0))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("step", choices=("render", "sheet"))
    p.add_argument("--out", type=Path)
    p.add_argument("--before", type=Path)
    p.add_argument("--after", type=Path)
    p.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    args = p.parse_args(argv)
    if args.step == "render":
        render(args.out, args.textures)
    else:
        sheet(args.before, args.after, args.textures)
    return 0


if __name__ == "__main__":
    sys.exit(main())
