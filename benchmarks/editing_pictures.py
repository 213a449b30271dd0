"""The before/after pictures of ``docs/editing.md`` (fill, transfer, guided synthesis).

Usage::

    PYTHONPATH=src python benchmarks/editing_pictures.py [--out docs/images]

Every input is an image every user has: the CC0 textures bundled with scikit-image
(``texsyn.data``: brick, gravel) and its public-domain ``astronaut`` photograph (NASA), so
the pictures can be made again anywhere. Each picture is a row of panels separated by light grey
gaps; the timings are printed (wall seconds on the machine that runs it).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import texsyn
from texsyn.editing import fill, synthesize_guided, transfer

REPO = Path(__file__).resolve().parents[1]


def row(panels: list[np.ndarray], gap: int = 6) -> np.ndarray:
    """Panels side by side (grey ones made RGB), top-aligned on a light grey background."""
    rgb = [np.repeat(p[..., None], 3, axis=2) if p.ndim == 2 else p for p in panels]
    height = max(p.shape[0] for p in rgb)
    width = sum(p.shape[1] for p in rgb) + gap * (len(rgb) - 1)
    sheet = np.full((height, width, 3), 0.8, np.float32)
    left = 0
    for p in rgb:
        sheet[: p.shape[0], left : left + p.shape[1]] = p
        left += p.shape[1] + gap
    return sheet


def timed(label: str, work):
    start = time.perf_counter()
    result = work()
    print(f"{label}: {time.perf_counter() - start:.2f} s", flush=True)
    return result


def fill_pictures(out: Path) -> None:
    from texsyn.io import write_image

    image = texsyn.data.exemplar("brick", size=128)
    hole = np.zeros(image.shape, bool)
    hole[44:84, 40:82] = True  # a square in the middle
    hole[100:, 0:30] = True  # and a corner touching two borders
    shown = np.repeat(image[..., None], 3, axis=2)
    shown[hole] = (1.0, 0.0, 1.0)  # the hole in magenta
    by_pixels = timed("fill efros_leung", lambda: fill(image, hole, method="efros_leung", rng=0).image)
    by_blocks = timed(
        "fill quilting", lambda: fill(image, hole, method="quilting", patch_size=24, rng=0).image
    )
    write_image(out / "editing_fill.png", row([shown, by_pixels, by_blocks]))


def transfer_pictures(out: Path) -> None:
    from skimage import data as skdata
    from skimage.transform import resize

    from texsyn.io import write_image
    from texsyn.ops.color import luma

    target = resize(luma(skdata.astronaut()[:300, 100:400] / 255.0), (150, 150), anti_aliasing=True)
    results = [target]
    for name in ("gravel", "brick"):
        texture = texsyn.data.exemplar(name, size=160)
        result = timed(
            f"transfer {name}",
            lambda texture=texture: transfer(texture, target, alpha=0.1, iterations=3, patch_size=18, rng=0),
        )
        results.append(result.image)
    write_image(out / "editing_transfer.png", row(results))


def guided_pictures(out: Path) -> None:
    from texsyn.io import write_image

    brick = texsyn.data.exemplar("brick", size=128)
    gravel = texsyn.data.exemplar("gravel", size=128)
    exemplar = np.concatenate([brick[:, :64], gravel[:, 64:]], axis=1)
    labels = np.zeros(exemplar.shape)
    labels[:, 64:] = 1.0
    y, x = np.mgrid[:160, :200]
    target = (((y - 80) / 55.0) ** 2 + ((x - 100) / 70.0) ** 2 < 1.0).astype(float)  # gravel in an ellipse
    result = timed(
        "guided quilting",
        lambda: synthesize_guided(exemplar, labels, target, weight=1.0, patch_size=16, rng=0),
    )
    write_image(out / "editing_guided.png", row([exemplar, labels, target, result.image]))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=REPO / "docs" / "images")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    fill_pictures(args.out)
    transfer_pictures(args.out)
    guided_pictures(args.out)


if __name__ == "__main__":
    main()
