"""Run every method over a folder of textures: median times and metrics, and cost vs size.

Usage::

    python benchmarks/bench_quality.py [--textures DIR] [--methods NAME ...] [--limit N]
                                       [--sizes 128 256 512 1024] [--budget SECONDS]
                                       [--out benchmarks/quality.md] [--plot benchmarks/time_vs_size.png]

For every image of ``--textures`` (``../shared/textures`` beside the repository by
default), cropped to at most 128x128, each method synthesises twice the exemplar size with
seed 0 and default parameters; the table gives, per method, the median wall time (fit +
sample) and the median of every metric of :func:`texsyn.metrics.evaluate`.

The second part times each method on one 128x128 colour exemplar for output sides of
``--sizes`` and plots time against size (log-log, needs matplotlib: ``pip install
-e .[bench]``); a method stops growing once one size took more than ``--budget`` seconds.
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
from texsyn.metrics import METRIC_DESCRIPTIONS, evaluate

REPO = Path(__file__).resolve().parents[1]
DEFAULT_TEXTURES = REPO.parent / "shared" / "textures"
SIZE_EXEMPLAR = "gh_tartavel_vistex/Brick-00.png"


def load_textures(folder: Path, limit: int | None) -> list[tuple[str, np.ndarray]]:
    paths = sorted(
        p
        for p in folder.rglob("*")
        if p.suffix.lower() in (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".gif", ".bmp")
    )
    if limit:
        paths = paths[:limit]
    out = []
    for path in paths:
        img = read_image(path)
        out.append((str(path.relative_to(folder)), img[:128, :128]))
    if not out:
        raise SystemExit(f"no images found in {folder}")
    return out


def quality_table(textures, methods) -> tuple[list[str], dict]:
    per_method: dict[str, dict[str, list[float]]] = {m: {"seconds": []} for m in methods}
    failures: dict[str, list[str]] = {m: [] for m in methods}
    for label, ex in textures:
        for name in methods:
            try:
                start = time.perf_counter()
                out = texsyn.make_method(name).fit(ex).sample(rng=0)
                seconds = time.perf_counter() - start
            except ValueError as exc:  # e.g. exemplar smaller than the method's patch
                failures[name].append(f"{label}: {exc}")
                continue
            scores = evaluate(out, ex)
            per_method[name]["seconds"].append(seconds)
            for key, value in scores.items():
                per_method[name].setdefault(key, []).append(value)
            print(
                f"{label:40s} {name:15s} {seconds:8.3f} s  coherence {scores['patch_coherence']:.4f}  copied {scores['copied_share']:.3f}",
                flush=True,
            )
    keys = list(METRIC_DESCRIPTIONS)
    lines = [
        "| method | textures | median time (s) | " + " | ".join(k.replace("_", " ") for k in keys) + " |",
        "|---|---:|---:|" + "---:|" * len(keys),
    ]
    for name in methods:
        data = per_method[name]
        if not data["seconds"]:
            lines.append(f"| {name} | 0 | | " + " | ".join("" for _ in keys) + " |")
            continue
        cells = " | ".join(f"{statistics.median(data[k]):.4g}" for k in keys)
        lines.append(
            f"| {name} | {len(data['seconds'])} | {statistics.median(data['seconds']):.3f} | {cells} |"
        )
    notes = [f"- {name}: skipped {f}" for name, fs in failures.items() for f in fs]
    return lines + ([""] + notes if notes else []), per_method


def size_sweep(exemplar, methods, sizes, budget) -> dict[str, list[tuple[int, float]]]:
    results: dict[str, list[tuple[int, float]]] = {}
    for name in methods:
        model = texsyn.make_method(name).fit(exemplar)
        results[name] = []
        for size in sizes:
            start = time.perf_counter()
            model.sample((size, size), rng=0)
            seconds = time.perf_counter() - start
            results[name].append((size, seconds))
            print(f"{name:15s} {size:5d}  {seconds:9.3f} s", flush=True)
            if seconds > budget:
                break
    return results


def plot(results, path: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot (pip install -e .[bench])")
        return False
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for name, points in results.items():
        xs, ys = zip(*points)
        ax.loglog(xs, ys, "o-", label=name)
    ax.set_xlabel("output side (pixels)")
    ax.set_ylabel("sample time (s)")
    ax.set_title("texsyn: time against output size (128x128 colour exemplar)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    parser.add_argument("--methods", nargs="*", default=sorted(texsyn.METHODS))
    parser.add_argument("--limit", type=int, default=None, help="use only the first N textures")
    parser.add_argument("--sizes", type=int, nargs="*", default=[128, 256, 512, 1024])
    parser.add_argument("--budget", type=float, default=60.0)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "quality.md")
    parser.add_argument("--plot", type=Path, default=REPO / "benchmarks" / "time_vs_size.png")
    args = parser.parse_args(argv)

    textures = load_textures(args.textures, args.limit)
    table, _ = quality_table(textures, args.methods)
    lines = [
        "# texsyn methods over a texture folder",
        "",
        f"{len(textures)} exemplars from `{args.textures.name}` (each cropped to at most 128x128), output twice "
        f"the exemplar, seed 0, default parameters. Machine: {platform.machine()}, {os.cpu_count()} CPUs, "
        f"numpy {np.__version__}, texsyn {texsyn.__version__}. Medians over exemplars.",
        "",
        *table,
        "",
        "Metrics: "
        + "; ".join(f"*{k.replace('_', ' ')}*: {v}" for k, v in METRIC_DESCRIPTIONS.items())
        + ".",
    ]
    if args.sizes:
        size_path = args.textures / SIZE_EXEMPLAR
        exemplar = read_image(size_path)[:128, :128] if size_path.exists() else textures[0][1]
        sweep = size_sweep(exemplar, args.methods, args.sizes, args.budget)
        lines += [
            "",
            "## Sample time against output size",
            "",
            "| method | " + " | ".join(f"{s}x{s}" for s in args.sizes) + " |",
            "|---|" + "---:|" * len(args.sizes),
        ]
        for name, points in sweep.items():
            got = dict(points)
            lines.append(
                f"| {name} | "
                + " | ".join(f"{got[s]:.3f}" if s in got else "(skipped)" for s in args.sizes)
                + " |"
            )
        lines.append(f"\nA method stops at the first size that took over {args.budget:g} s.")
        if plot(sweep, args.plot):
            lines.append(f"\n![time against size]({args.plot.name})")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
