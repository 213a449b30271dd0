"""Time every registered method on 128x128 exemplars synthesised to 256x256, grey and colour.

Usage::

    python benchmarks/bench_methods.py [--textures DIR] [--repeats N] [--methods NAME ...]
                                       [--out benchmarks/results.md]

Exemplars are read from ``../shared/textures`` beside the repository by default (or any
folder of images given with ``--textures``); each is cropped to its top-left 128x128
square, and its BT.601 luma is used for the grey cases. Times are medians over textures and
repeats, for ``fit`` and ``sample`` together and for ``sample`` alone. The table is printed
and written as markdown. Timings belong here, not in the test suite.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import texsyn
from texsyn.io import read_image
from texsyn.ops import rgb_to_yuv

REPO = Path(__file__).resolve().parents[1]
DEFAULT_TEXTURES = REPO.parent / "shared" / "textures"
DEFAULT_FILES = [
    "gh_tartavel_vistex/Brick-00.png",
    "gh_tartavel_vistex/Sand-01.png",
    "gh_tartavel_vistex/Fabric-13.png",
]
#: targets of the method issues (seconds, median, fit + sample)
TARGETS = {
    ("random_phase", "colour", 512): 0.05,
    ("quilting", "colour", 256): 0.5,
    ("heeger_bergen", "colour", 256): 1.5,
    ("efros_leung", "grey", 256): 20.0,
    ("mslg", "colour", 256): 5.0,
    ("lg", "colour", 256): 5.0,
    ("clg", "colour", 256): 10.0,
    ("rclg", "colour", 256): 10.0,
    ("cwt", "grey", 256): 2.0,
    ("cwt", "colour", 256): 3.0,
    ("sparse", "colour", 256): 60.0,
    ("patch_wavelet", "colour", 256): 10.0,
    ("grouplets", "colour", 256): 10.0,
    ("grouplets", "grey", 256): 10.0,
    ("portilla_simoncelli", "grey", 256): 3.0,
    ("portilla_simoncelli", "colour", 256): 8.0,
}


def load_exemplars(folder: Path, names: list[str] | None) -> list[tuple[str, np.ndarray]]:
    if names:
        paths = [folder / n for n in names]
    else:
        paths = sorted(p for p in folder.rglob("*") if p.suffix.lower() in (".png", ".jpg", ".tif", ".gif"))
    out = []
    for path in paths:
        img = read_image(path)
        if img.ndim == 3 and min(img.shape[:2]) >= 128:
            out.append((path.stem, img[:128, :128]))
    if not out:
        raise SystemExit(f"no colour exemplar of at least 128x128 found in {folder}")
    return out


def time_case(name: str, exemplar: np.ndarray, size: int, seed: int) -> tuple[float, float]:
    start = time.perf_counter()
    method = texsyn.make_method(name).fit(exemplar)
    fitted = time.perf_counter()
    method.sample((size, size), rng=seed)
    end = time.perf_counter()
    return end - start, end - fitted


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    parser.add_argument(
        "--files", nargs="*", default=None, help="files inside --textures (default: three VisTex crops)"
    )
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--methods", nargs="*", default=sorted(texsyn.METHODS))
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results.md")
    args = parser.parse_args(argv)

    files = (
        args.files
        if args.files is not None
        else (DEFAULT_FILES if args.textures == DEFAULT_TEXTURES else None)
    )
    exemplars = load_exemplars(args.textures, files)
    cases = [(m, kind, 256) for m in args.methods for kind in ("grey", "colour")]
    if "random_phase" in args.methods:
        cases.append(("random_phase", "colour", 512))

    # warm-up: compile numba kernels and import lazily loaded modules outside the timings
    warm = exemplars[0][1][:64, :64]
    for m in args.methods:
        for image in (warm, np.clip(rgb_to_yuv(warm)[..., 0], 0, 1)):
            texsyn.make_method(m).fit(image).sample((24, 24), rng=0)

    rows = []
    for name, kind, size in cases:
        totals, samples = [], []
        repeats = args.repeats
        for _label, ex in exemplars:
            image = ex if kind == "colour" else np.clip(rgb_to_yuv(ex)[..., 0], 0, 1)
            for r in range(repeats):
                total, sample = time_case(name, image, size, seed=r)
                totals.append(total)
                samples.append(sample)
                if total > 10 and r == 0:
                    break  # slow methods: one run per exemplar is enough
        target = TARGETS.get((name, kind, size))
        median = statistics.median(totals)
        verdict = "" if target is None else ("yes" if median < target else "**no**")
        rows.append(
            (name, kind, f"128 -> {size}", median, statistics.median(samples), len(totals), target, verdict)
        )
        print(
            f"{name:15s} {kind:6s} {size:4d}  total {median:8.3f} s  sample {statistics.median(samples):8.3f} s",
            flush=True,
        )

    lines = [
        "# texsyn method timings",
        "",
        f"Exemplars: {', '.join(label for label, _ in exemplars)} (top-left 128x128 crops; grey = BT.601 luma).",
        f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
        f"numpy {np.__version__}, texsyn {texsyn.__version__}. Default parameters, medians over "
        f"exemplars x repeats (up to {args.repeats}).",
        "",
        "| method | image | size | fit + sample (s) | sample (s) | runs | target (s) | meets target |",
        "|---|---|---|---:|---:|---:|---:|---|",
    ]
    for name, kind, size, total, sample, runs, target, verdict in rows:
        tgt = "" if target is None else f"{target:g}"
        lines.append(
            f"| {name} | {kind} | {size} | {total:.3f} | {sample:.3f} | {runs} | {tgt} | {verdict} |"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
