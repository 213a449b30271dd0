"""Fluid textures over 300 frames (Peyré 2008, Table 2; issue 18): do they stay alive?

Usage::

    python benchmarks/bench_fluid_textures.py [--textures DIR] [--frames 300] [--size 256]
        [--out benchmarks/fluid_textures.md] [--images benchmarks/results]

For two oriented exemplars (straw, Fabric-13, and herringbone, Fabric-02, from
``../shared/textures``) and default parameters, animates ``--frames`` frames of ``--size``
pixels and reports, for frames 1, 100 and 300: the pixel-histogram distance to the exemplar,
the Laplacian band energies at every scale (relative to the exemplar's and to frame 1's),
the structure-tensor coherence; and over the run: the mean displacement per frame, the mean
|cos| between the first and last flow directions, the temporal coherence (a frame against
the previous frame warped by the flow, over the frame against an independent synthesis), the
wall time and the peak resident memory. Writes a contact sheet of frames 1/100/300 per
exemplar to ``--images`` (``fluid_<name>_frames.png``; the exemplars are not included).
"""

from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

import numpy as np
from _common import machine, parser

import texsyn
from texsyn.io import read_image, write_image
from texsyn.metrics import histogram_distance, laplacian_band_energies, mean_coherence
from texsyn.ops.fluid import advect

EXEMPLARS = {
    "straw": "gh_tartavel_vistex/Fabric-13.png",
    "herringbone": "gh_tartavel_vistex/Fabric-02.png",
}
#: the detail bands of the method's own Laplacian tight frame (parameter `levels`)
LEVELS = 3


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run(name: str, path: Path, n_frames: int, size: int, images: Path) -> dict:
    exemplar = read_image(path)
    method = texsyn.make_method("grouplets")
    start = time.perf_counter()
    method.fit(exemplar)
    kept: dict[int, np.ndarray] = {}
    flows: dict[int, np.ndarray] = {}
    displacement = []
    pairs = []  # (previous frame, its flow, frame, its flow) at the probes, judged after timing
    previous = None
    picks = sorted({0, min(99, n_frames - 1), n_frames - 1})
    probes = set(range(min(25, n_frames - 1), n_frames, 50))
    for frame in method.animate(n_frames, (size, size), rng=0):
        image = frame.image.astype(np.float64)
        displacement.append(float(np.mean(np.hypot(*(method.tau * frame.flow).transpose(2, 0, 1)))))
        if frame.index in picks:
            kept[frame.index] = image
        if frame.index in (0, n_frames - 1):
            flows[frame.index] = frame.flow
        if previous is not None and frame.index in probes:
            pairs.append((*previous, image, frame.flow, frame.index))
        previous = (image, frame.flow)
    seconds = time.perf_counter() - start
    warp_ratio = []
    for before, flow, image, now, index in pairs:
        warped = advect(before, flow, method.tau, order=3)
        independent = method.synthesize_along(now, rng=1000 + index).astype(np.float64)
        warp_ratio.append(float(np.abs(image - warped).mean() / np.abs(image - independent).mean()))
    first, last = flows[0], flows[n_frames - 1]
    unit = [f / np.maximum(np.linalg.norm(f, axis=-1, keepdims=True), 1e-12) for f in (first, last)]
    cosine = float(np.mean(np.abs(np.sum(unit[0] * unit[1], axis=-1))))
    reference = laplacian_band_energies(exemplar, LEVELS)
    rows = []
    for index in picks:
        image = kept[index]
        energies = laplacian_band_energies(image, LEVELS)
        rows.append(
            {
                "frame": index + 1,
                "histogram": histogram_distance(image, exemplar),
                "vs_exemplar": energies / reference,
                "vs_first": energies / laplacian_band_energies(kept[0], LEVELS),
                "coherence": mean_coherence(image),
            }
        )
    sheet = np.concatenate([np.clip(kept[i], 0, 1) for i in picks], axis=1)
    images.mkdir(parents=True, exist_ok=True)
    write_image(images / f"fluid_{name}_frames.png", sheet.astype(np.float32), overwrite=True)
    return {
        "name": name,
        "file": path.name,
        "seconds": seconds,
        "rows": rows,
        "exemplar_coherence": mean_coherence(exemplar),
        "displacement": float(np.mean(displacement[1:])),
        "cosine": cosine,
        "warp_ratio": warp_ratio,
    }


def fmt(values) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__.splitlines()[0], "fluid_textures.md")
    p.add_argument("--frames", type=int, default=300)
    p.add_argument("--size", type=int, default=256)
    args = p.parse_args(argv)
    results = [run(n, args.textures / f, args.frames, args.size, args.images) for n, f in EXEMPLARS.items()]
    lines = [
        "# Fluid textures over time (Peyré 2008, Table 2; issue 18)",
        "",
        machine() + f" Peak RSS {peak_rss_mib():.0f} MiB.",
        "",
        f"Default parameters, {args.frames} frames of {args.size}x{args.size}, seed 0; "
        f"`python benchmarks/bench_fluid_textures.py`. Band energies: mean squared coefficient "
        f"per pixel of the Laplacian tight frame ({LEVELS} detail bands, finest first, then "
        "the low-pass), as a ratio.",
        "",
        "| exemplar | frame | histogram distance | band energy / exemplar | band energy / frame 1 | coherence (exemplar) |",
        "|---|---:|---:|---|---|---:|",
    ]
    for r in results:
        for row in r["rows"]:
            lines.append(
                f"| {r['name']} ({r['file']}) | {row['frame']} | {row['histogram']:.4f} | "
                f"{fmt(row['vs_exemplar'])} | {fmt(row['vs_first'])} | "
                f"{row['coherence']:.2f} ({r['exemplar_coherence']:.2f}) |"
            )
    lines += [
        "",
        "| exemplar | time (s) | s / frame | mean displacement (px / frame) | mean abs cos, first vs last flow | warped difference / independent difference (max) | contact sheet |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in results:
        lines.append(
            f"| {r['name']} | {r['seconds']:.1f} | {r['seconds'] / args.frames:.3f} | "
            f"{r['displacement']:.2f} | {r['cosine']:.2f} | {max(r['warp_ratio']):.3f} | "
            f"results/fluid_{r['name']}_frames.png |"
        )
    text = "\n".join(lines) + "\n"
    args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
