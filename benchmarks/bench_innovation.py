"""Verbatim copies per exemplar: the largest copied region of each method's output.

Usage::

    python benchmarks/bench_innovation.py [--textures DIR] [--files F ...] [--methods M ...]
                                          [--out benchmarks/innovation.md]

For each exemplar (top-left crop of at most 128x128) and method (default parameters,
seed 0, output twice the exemplar), reports ``largest_copy`` and ``copied_share`` of
:func:`texsyn.metrics.copy_map` as fractions of the output area.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import texsyn
from texsyn.io import read_image
from texsyn.metrics import copy_map

REPO = Path(__file__).resolve().parents[1]
DEFAULT_TEXTURES = REPO.parent / "shared" / "textures"
DEFAULT_FILES = [
    "gh_tartavel_vistex/Brick-00.png",
    "gh_tartavel_vistex/Sand-01.png",
    "gh_tartavel_vistex/Fabric-13.png",
    "gh_tartavel_vistex/Flowers-00.png",
    "gh_quilting/t4.png",
    "gh_lcv_textureSynth/text.png",
    "gh_efros_leung/color_4.png",
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    parser.add_argument("--files", nargs="*", default=DEFAULT_FILES)
    parser.add_argument("--methods", nargs="*", default=["quilting", "lg", "mslg"])
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "innovation.md")
    args = parser.parse_args(argv)

    lines = [
        "# Largest verbatim-copied region (share of the output area)",
        "",
        "Default parameters, seed 0, output twice the exemplar (top-left crops of at most 128x128). "
        "Each cell: largest copied region / share of the output in copies of at least 16x16 pixels "
        "(exact nearest 7x7 patches within a per-value MSE of 1e-4).",
        "",
        "| exemplar | " + " | ".join(args.methods) + " |",
        "|---|" + "---:|" * len(args.methods),
    ]
    for name in args.files:
        ex = read_image(args.textures / name)[:128, :128]
        cells = []
        for method in args.methods:
            out = texsyn.make_method(method).fit(ex).sample(rng=0)
            cm = copy_map(out, ex)
            cells.append(f"{cm.largest:.3f} / {cm.copied_share:.3f}")
            print(
                f"{name:40s} {method:10s} largest {cm.largest:.3f}  copied {cm.copied_share:.3f}", flush=True
            )
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
