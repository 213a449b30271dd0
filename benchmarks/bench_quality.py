"""Run every method over a folder of textures: median times and metrics, and cost vs size.

Usage::

    python benchmarks/bench_quality.py [--textures DIR] [--methods NAME ...] [--limit N]
                                       [--grey] [--details FILE] [--sheets DIR]
                                       [--store DIR [--only NAME ...] [--cached]] [--start N]
                                       [--sizes 128 256 512 1024] [--budget SECONDS]
                                       [--out benchmarks/quality.md] [--plot benchmarks/time_vs_size.png]

For every image of ``--textures`` (``../shared/textures`` beside the repository by
default), cropped to at most 128x128, each method synthesises twice the exemplar size with
seed 0 and default parameters (with ``--grey``, colour exemplars are also run as their
luma); the table gives, per method, the median wall time (fit + sample), the median of every
metric of :func:`texsyn.metrics.evaluate` and how many outputs keep both the sharpness and
the contrast ratio within 0.8-1.2. ``--details`` writes one table per method with every
exemplar's figures; ``--sheets`` writes one contact sheet per exemplar (the exemplar, then
each method's output, in the order of ``--methods``; none for the luma runs). ``--store DIR`` keeps every output
and its scores; a later run with ``--only NAME ...`` runs only those methods again and reads
the others back (a method changed, the rest not); ``--start N`` skips the first textures (a
long run split over processes, each with its own store), and ``--cached`` runs nothing and
reports what the store holds.

The second part times each method on one 128x128 colour exemplar for output sides of
``--sizes`` and plots time against size (log-log, needs matplotlib: ``pip install
-e .[bench]``); a method stops growing once one size took more than ``--budget`` seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import texsyn
from texsyn.io import read_image, write_image
from texsyn.metrics import METRIC_DESCRIPTIONS, evaluate
from texsyn.ops import luma

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


def with_grey(textures):
    """The textures, and every colour one also as its luma (label suffixed ' (grey)')."""
    out = []
    for label, ex in textures:
        out.append((label, ex))
        if ex.ndim == 3:
            out.append((f"{label} (grey)", luma(ex).astype(np.float32)))
    return out


def within(scores: dict) -> bool:
    """Sharpness and contrast ratios both within 0.8-1.2 (issue 19's acceptance band)."""
    return all(0.8 <= scores[k] <= 1.2 for k in ("sharpness_ratio", "contrast_ratio"))


def contact_sheet(exemplar: np.ndarray, outputs: list[np.ndarray]) -> np.ndarray:
    """The exemplar (top-left of a tile) then each output, side by side, 4-pixel gaps."""
    tiles = [exemplar] + outputs
    side = max(t.shape[0] for t in tiles)
    rgb = [np.repeat(t[..., None], 3, axis=2) if t.ndim == 2 else t for t in tiles]
    padded = [np.pad(t, ((0, side - t.shape[0] + 4), (0, 4), (0, 0)), constant_values=1.0) for t in rgb]
    return np.concatenate([p[:side] for p in padded], axis=1)


def stem_of(label: str) -> str:
    """File-name stem of a texture label ('dir/name.png (grey)' -> 'dir_name_grey')."""
    grey = label.endswith(" (grey)")
    return label.removesuffix(" (grey)").rsplit(".", 1)[0].replace("/", "_") + ("_grey" if grey else "")


class Store:
    """Outputs and scores kept between runs (``--store``): a method left out of ``--only``
    is read back instead of run again, so one method can be rerun after a change."""

    def __init__(self, folder: Path | None):
        self.folder = folder
        self.index: dict = {}
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            path = folder / "scores.json"
            self.index = json.loads(path.read_text()) if path.exists() else {}

    def get(self, label: str, name: str):
        entry = self.index.get(f"{label}|{name}")
        if entry is None or self.folder is None:
            return None
        return read_image(self.folder / entry["file"]), entry["seconds"], entry["scores"]

    def put(self, label: str, name: str, out: np.ndarray, seconds: float, scores: dict) -> None:
        if self.folder is None:
            return
        file = f"{stem_of(label)}__{name}.png"
        write_image(self.folder / file, np.clip(out, 0.0, 1.0), overwrite=True)
        self.index[f"{label}|{name}"] = {"file": file, "seconds": seconds, "scores": scores}
        (self.folder / "scores.json").write_text(json.dumps(self.index, indent=0, sort_keys=True))


def quality_table(
    textures, methods, details=None, sheets=None, store=None, only=None, sheet_ext="png", cached_only=False
) -> tuple[list[str], dict]:
    per_method: dict[str, dict[str, list[float]]] = {m: {"seconds": []} for m in methods}
    failures: dict[str, list[str]] = {m: [] for m in methods}
    rows: dict[str, list[str]] = {m: [] for m in methods}
    keys = list(METRIC_DESCRIPTIONS)
    store = store or Store(None)
    for label, ex in textures:
        outputs = []
        for name in methods:
            kept = None if only is None or name in only else store.get(label, name)
            if kept is not None:
                out, seconds, scores = kept
                outputs.append(out)
            elif cached_only:
                failures[name].append(f"{label}: not run")
                outputs.append(np.ones((2 * ex.shape[0], 2 * ex.shape[1]) + ex.shape[2:], np.float32))
                continue
            else:
                try:
                    start = time.perf_counter()
                    out = texsyn.make_method(name).fit(ex).sample(rng=0)
                    seconds = time.perf_counter() - start
                except ValueError as exc:  # e.g. exemplar smaller than the method's patch
                    failures[name].append(f"{label}: {exc}")
                    outputs.append(np.ones((2 * ex.shape[0], 2 * ex.shape[1]) + ex.shape[2:], np.float32))
                    continue
                outputs.append(out)
                scores = {k: float(v) for k, v in evaluate(out, ex).items()}
                store.put(label, name, out, seconds, scores)
            per_method[name]["seconds"].append(seconds)
            per_method[name].setdefault("within", []).append(float(within(scores)))
            for key, value in scores.items():
                per_method[name].setdefault(key, []).append(value)
            rows[name].append(
                f"| {label} | {seconds:.2f} | " + " | ".join(f"{scores[k]:.4g}" for k in keys) + " |"
            )
        if sheets is not None and not label.endswith(" (grey)"):  # the luma runs get no sheet
            sheets.mkdir(parents=True, exist_ok=True)
            write_image(
                sheets / f"sheet_{stem_of(label)}.{sheet_ext}", contact_sheet(ex, outputs), overwrite=True
            )
            print(
                f"{label:40s} {name:15s} {seconds:8.3f} s  coherence {scores['patch_coherence']:.4f}  copied {scores['copied_share']:.3f}",
                flush=True,
            )
    lines = [
        "| method | textures | median time (s) | sharpness and contrast in 0.8-1.2 | "
        + " | ".join(k.replace("_", " ") for k in keys)
        + " |",
        "|---|---:|---:|---:|" + "---:|" * len(keys),
    ]
    for name in methods:
        data = per_method[name]
        if not data["seconds"]:
            lines.append(f"| {name} | 0 | | | " + " | ".join("" for _ in keys) + " |")
            continue
        cells = " | ".join(f"{statistics.median(data[k]):.4g}" for k in keys)
        lines.append(
            f"| {name} | {len(data['seconds'])} | {statistics.median(data['seconds']):.3f} | "
            f"{int(sum(data['within']))} | {cells} |"
        )
    notes = [f"- {name}: skipped {f}" for name, fs in failures.items() for f in fs]
    if details is not None:
        text = ["# Every exemplar, method by method", ""]
        for name in methods:
            text += [
                f"## {name}",
                "",
                "| exemplar | time (s) | " + " | ".join(k.replace("_", " ") for k in keys) + " |",
                "|---|---:|" + "---:|" * len(keys),
                *rows[name],
                "",
            ]
        details.write_text("\n".join(text))
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
    parser.add_argument("--grey", action="store_true", help="also run colour exemplars as their luma")
    parser.add_argument("--details", type=Path, default=None, help="one table per method, every exemplar")
    parser.add_argument("--sheets", type=Path, default=None, help="a contact sheet per exemplar here")
    parser.add_argument(
        "--store",
        type=Path,
        default=None,
        help="keep outputs and scores here; reuse them for methods not in --only",
    )
    parser.add_argument("--only", nargs="*", default=None, help="with --store: run only these methods again")
    parser.add_argument("--start", type=int, default=0, help="skip the first N textures (after --grey)")
    parser.add_argument(
        "--cached", action="store_true", help="with --store: run nothing, report what it holds"
    )
    parser.add_argument(
        "--sheet-ext", default="png", choices=("png", "jpg"), help="file type of the contact sheets"
    )
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "quality.md")
    parser.add_argument("--plot", type=Path, default=REPO / "benchmarks" / "time_vs_size.png")
    args = parser.parse_args(argv)

    textures = load_textures(args.textures, args.limit)
    if args.grey:
        textures = with_grey(textures)
    textures = textures[args.start :]
    table, _ = quality_table(
        textures,
        args.methods,
        args.details,
        args.sheets,
        Store(args.store),
        [] if args.cached else args.only,
        args.sheet_ext,
        args.cached,
    )
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
