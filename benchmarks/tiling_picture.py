"""Make the picture of docs/tiling.md and the README: an output tiled 2x2, without and with
``tileable=True``.

    python benchmarks/tiling_picture.py [--method quilting] [--out docs/images/tiling.png]

The exemplar is scikit-image's brick wall (CC0, built in); nothing is downloaded.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import texsyn
from texsyn.io import write_image

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="quilting")
    parser.add_argument("--size", type=int, default=192)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "tiling.png")
    args = parser.parse_args()
    exemplar = texsyn.data.exemplar("brick", size=128)
    model = texsyn.make_method(args.method).fit(exemplar)
    shape = (args.size, args.size)
    plain = np.tile(model.sample(shape, rng=args.seed), (2, 2))
    tiled = np.tile(model.sample(shape, rng=args.seed, tileable=True), (2, 2))
    gap = np.ones((plain.shape[0], 12), dtype=np.float32)
    write_image(args.out, np.concatenate([plain, gap, tiled], axis=1))
    print(f"wrote {args.out}: left, {args.method} tiled 2x2; right, the same with tileable=True")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
