"""Peyré 2008 grouplets: static and dynamic timings, geometry fidelity, statistics over time.

Usage::

    python benchmarks/bench_grouplets.py [--textures DIR] [--out benchmarks/grouplets.md]

Measures on this machine (medians):

* static synthesis 128x128 -> 256x256 with default parameters (target 10 s), colour and grey;
* dynamic synthesis of 60 frames at 128x128 (target 30 s) and 256x256 (target 2 min);
* geometry: a static synthesis along a vortex, the mean |cos| between the output's
  structure-tensor orientation and the vortex, over output pixels of coherence > 0.5;
* statistics over time: histogram distance to the exemplar and band-energy profile (Laplacian
  tight frame, luma) of frame 1 and frame 60.

Images and GIFs go to ``benchmarks/results/`` (not committed).
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np
from _common import machine, parser

import texsyn
from texsyn.io import read_image, write_frames, write_image
from texsyn.metrics import histogram_distance
from texsyn.ops import luma
from texsyn.ops.flow import builtin_flow, structure_tensor_orientation
from texsyn.ops.pyramids import LaplacianTightFrame

STATIC_FILES = [
    "gh_tartavel_vistex/Bark-10.png",
    "gh_tartavel_vistex/Water-05.png",
    "gh_tartavel_vistex/Brick-02.png",
]
DYNAMIC_FILES = ["gh_tartavel_vistex/Bark-10.png", "gh_tartavel_vistex/Water-05.png"]


def band_profile(image: np.ndarray) -> np.ndarray:
    g = luma(np.asarray(image, dtype=np.float64))
    frame = LaplacianTightFrame(g.shape, 3)
    return np.sum(frame.forward(g - g.mean()) ** 2, axis=(1, 2))


def main(argv: list[str] | None = None) -> int:
    args = parser(__doc__.splitlines()[0], "grouplets.md").parse_args(argv)
    args.images.mkdir(parents=True, exist_ok=True)
    lines = [
        "# Grouplets (Peyré 2008)",
        "",
        machine() + " Default parameters unless stated.",
        "",
    ]
    warm = read_image(args.textures / STATIC_FILES[0])[:32, :32]
    list(texsyn.animate(warm, 2, (32, 32), rng=0, n_iterations=1))

    # ------------------------------------------------------------------ static timings
    lines += [
        "## Static synthesis 128x128 -> 256x256 (target 10 s)",
        "",
        "| exemplar | image | fit + sample (s) | histogram distance | image |",
        "|---|---|---:|---:|---|",
    ]
    totals = {"colour": [], "grey": []}
    for name in STATIC_FILES:
        ex = read_image(args.textures / name)[:128, :128]
        for kind, image in (("colour", ex), ("grey", luma(ex).astype(np.float32))):
            times = []
            for seed in range(args.repeats):
                t0 = time.perf_counter()
                out = texsyn.make_method("grouplets").fit(image).sample((256, 256), rng=seed)
                times.append(time.perf_counter() - t0)
            total = statistics.median(times)
            totals[kind].append(total)
            file = f"grouplets_static_{Path(name).stem}_{kind}.png"
            write_image(args.images / file, out)
            lines.append(
                f"| {Path(name).stem} | {kind} | {total:.2f} | {histogram_distance(out, image):.4f} | {file} |"
            )
            print(lines[-1], flush=True)
    lines += [
        "",
        f"Median: colour **{statistics.median(totals['colour']):.2f} s**, grey **{statistics.median(totals['grey']):.2f} s** (target 10 s).",
        "",
    ]

    # ------------------------------------------------------------------ geometry follows the flow
    lines += [
        "## Geometry follows a given flow",
        "",
        "Static synthesis 256x256 along the flow; mean |cos| between the output's structure-tensor orientation "
        "(sigma 5) and the flow over output pixels of coherence > 0.5 (target 0.9).",
        "",
        "| exemplar (mean coherence) | flow | coherent pixels | mean abs cos | image |",
        "|---|---|---:|---:|---|",
    ]
    for name in ("gh_tartavel_vistex/Bark-10.png", "gh_tartavel_vistex/Brick-02.png"):
        ex = read_image(args.textures / name)[:128, :128]
        _, coh_in = structure_tensor_orientation(luma(ex))
        method = texsyn.make_method("grouplets").fit(ex)
        for flow_name in ("vortex", "sources", "constant:30"):
            flow = builtin_flow(flow_name, (256, 256))
            out = method.synthesize_along(flow, rng=0)
            orientation, coherence = structure_tensor_orientation(luma(out))
            unit = flow / np.maximum(np.linalg.norm(flow, axis=-1, keepdims=True), 1e-12)
            cos = np.abs(np.sum(orientation * unit, axis=-1))
            keep = coherence > 0.5
            file = f"grouplets_flow_{Path(name).stem}_{flow_name.replace(':', '')}.png"
            write_image(args.images / file, out)
            lines.append(
                f"| {Path(name).stem} ({coh_in.mean():.2f}) | {flow_name} | {keep.mean():.2f} | {cos[keep].mean():.3f} | {file} |"
            )
            print(lines[-1], flush=True)
    lines.append("")

    # ------------------------------------------------------------------ dynamic
    lines += [
        "## Dynamic synthesis, 60 frames (targets: 30 s at 128x128, 2 min at 256x256)",
        "",
        "| exemplar | size | time (s) | hist. distance frame 1 / 60 | band energies frame 1 | band energies frame 60 | largest band change | RMS speed 1 / 60 | video |",
        "|---|---|---:|---|---|---|---:|---|---|",
    ]
    for name in DYNAMIC_FILES:
        ex = read_image(args.textures / name)[:128, :128]
        for size in (128, 256):
            t0 = time.perf_counter()
            frames = list(texsyn.animate(ex, 60, (size, size), rng=0))
            elapsed = time.perf_counter() - t0
            first, last = frames[1], frames[59]
            p1, p60 = band_profile(first.image), band_profile(last.image)
            change = np.max(np.abs(p60 - p1) / p1)
            speed = lambda f: float(np.sqrt(np.mean(np.sum(f.flow**2, axis=-1))))  # noqa: E731
            file = f"grouplets_dynamic_{Path(name).stem}_{size}.gif"
            write_frames(args.images / file, (f.image for f in frames), fps=24)
            lines.append(
                f"| {Path(name).stem} | {size} | {elapsed:.1f} | {histogram_distance(first.image, ex):.4f} / {histogram_distance(last.image, ex):.4f} "
                f"| {', '.join(f'{v:.1f}' for v in p1)} | {', '.join(f'{v:.1f}' for v in p60)} | {change:.1%} | {speed(first):.3f} / {speed(last):.3f} | {file} |"
            )
            print(lines[-1], flush=True)
    lines.append("")
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
