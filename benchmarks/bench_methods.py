"""Time, CPU and peak memory of every method, in process and as a whole ``texsyn synth`` process.

Usage::

    python benchmarks/bench_methods.py [--repeats 3] [--methods NAME ...] [--skip-scaling]
                                       [--scaling-sizes 256 512 1024 2048] [--big]
                                       [--out benchmarks/results.md]

Three parts, written to ``benchmarks/results.md`` with the machine line (issue 20,
``docs/performance.md``):

1. **Whole process**, 128 -> 256 grey and colour (the top-left 128x128 of Brick-00, its
   BT.601 luma for grey): ``texsyn synth EXEMPLAR -m METHOD --size 256x256 --seed 0 -q -o
   out.png`` run ``--repeats`` times; median wall time, CPU time (user + system of the child,
   every thread) and peak resident set (``wait4``'s ``ru_maxrss``), against issue 20's
   targets.
2. **In process**: each case in a fresh interpreter that first runs a small warm-up of the
   method (imports, numba compilation and cache loading, thread pools: the start-up the
   first part measures), numba and its first kernel loaded before it (some methods load them
   only from some size on: they are the libraries' memory, not the method's), then ``fit``
   + ``sample`` ``--repeats`` times; median wall, CPU, and the peak resident set growth
   over the warm-up (``VmHWM`` reset through ``/proc/self/clear_refs``, after the allocator
   gave back what earlier runs freed: ``malloc_trim``). With it, the arithmetic the method
   needs (a model of its dominant term, :data:`WORK`) over the time it takes: GFLOP/s.
3. **Scaling**: 128 -> 256 ... 2048 colour in process, one run per size (slow methods stop
   at the first size over ``--scaling-budget`` seconds), with two log-log plots
   (``benchmarks/results/time_vs_size.png``, ``memory_vs_size.png``) and the growth per
   doubling of the side (4 is linear in the pixels).

``--big`` adds ``texsyn synth -m quilting --size 8192x8192`` to a PNG (whole process, peak
RSS): the output is streamed band by band (``TextureSynthesizer.sample_rows``).
Timings belong here, not in the test suite.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (
    DEFAULT_TEXTURES,
    REPO,
    RESULTS,
    machine,
    peak_reset,
    status_kib,
    time_process,
    write_report,
)

EXEMPLAR = "gh_tartavel_vistex/Brick-00.png"

#: issue 20's targets: whole ``texsyn synth`` process, 128 -> 256, seconds
PROCESS_TARGETS = {
    ("quilting", "colour"): 0.45,
    ("heeger_bergen", "colour"): 0.8,
    ("portilla_simoncelli", "colour"): 3.0,
    ("portilla_simoncelli", "grey"): 1.2,
    ("efros_leung", "colour"): 5.0,
    ("sparse", "colour"): 15.0,
    ("wei_levoy", "colour"): 2.0,
    ("patch_wavelet", "colour"): 2.0,
    ("grouplets", "colour"): 2.0,
}

#: small settings of the warm-up run in each child (imports, compilation)
WARM_SIZE = 48

#: the in-process worker (``--child``) prints one JSON line per case
CHILD = "child"


def fft_flops(n: float) -> float:
    """Floating-point operations of one complex FFT of ``n`` points (``5 n log2 n``)."""
    return 5.0 * n * math.log2(max(n, 2.0))


def work_model(method: str, ex_shape: tuple[int, ...], out: tuple[int, int]) -> tuple[float, str]:
    """Floating-point operations of a method's dominant term at default parameters, and what it counts.

    Each is a lower bound of the arithmetic the method's algorithm needs (the cost its paper's
    loop implies), not a count of what the code does: the ratio to the time taken says how
    close the implementation runs to the machine.
    """
    h, w = ex_shape[:2]
    c = 1 if len(ex_shape) == 2 else ex_shape[2]
    pixels = float(out[0] * out[1])
    if method == "efros_leung":
        window, windows = 15, float((h - 14) * (w - 14))
        return (
            3.0 * pixels * windows * window * window * c,
            "masked SSD of every output pixel's window with every exemplar window",
        )
    if method == "quilting":
        b, step = 32, 27
        blocks = math.ceil(out[0] / step) * math.ceil(out[1] / step)
        spectrum = float((h + b) * (w + b))
        return blocks * (c + 2) * 2 * fft_flops(
            spectrum
        ), "per block, FFT correlations of the overlap with the exemplar"
    if method in ("heeger_bergen", "portilla_simoncelli"):
        iterations, bands = (5, 4 * 4 + 2) if method == "heeger_bergen" else (50, 4 * 4 * 2 + 2)
        return iterations * c * 2 * bands * fft_flops(
            pixels
        ), "per iteration, forward and inverse FFT of every band"
    if method == "random_phase":
        return 2 * c * fft_flops(pixels), "one FFT and one inverse FFT per channel"
    if method in ("lg", "clg", "rclg", "mslg"):
        patch, neighbours = 10, 50
        patches = float((h - patch + 1) * (w - patch + 1))
        blocks = pixels / (patch // 2) ** 2
        return blocks * patches * patch * patch * c * 3.0 + blocks * neighbours * (patch * patch * c) ** 2, (
            "nearest patches of every block, then a Gaussian of its neighbours"
        )
    if method == "wei_levoy":
        neighbourhood, levels = 12 * c, 4
        return 3.0 * pixels * (4.0 / 3.0) * h * w * neighbourhood * 2, (
            f"exact search of every pixel's causal neighbourhood over {levels} levels"
        )
    if method == "cwt":
        return (
            3.0 * pixels * h * w * 12 * c / 16.0,
            "nearest windows at the coarsest level, coherent candidates above",
        )
    if method == "patch_wavelet":
        return (
            2.0 * pixels * h * w * 8 * 8 * c / 16.0,
            "nearest exemplar patches of the output's patches at every level",
        )
    if method == "sparse":
        atoms, patch, sparsity = 384, 12, 4
        return (
            2.0 * pixels * atoms * patch * patch * c * sparsity * 10,
            "OMP of every patch on the dictionary, 10 rounds",
        )
    if method == "grouplets":
        return 10 * 20.0 * pixels * c * 6, "grouplet transform and histogram matching, 10 iterations"
    return float("nan"), ""


# ---------------------------------------------------------------------------- the exemplar
def exemplar(textures: Path, kind: str) -> np.ndarray:
    import texsyn.io

    image = texsyn.io.read_image(textures / EXEMPLAR)[:128, :128]
    if kind == "grey":
        from texsyn.ops import rgb_to_yuv

        image = np.clip(rgb_to_yuv(image)[..., 0], 0, 1).astype(np.float32)
    return image


# ---------------------------------------------------------------------------- in process
def run_child(
    method: str, kind: str, sizes: list[int], repeats: int, textures: Path, budget: float
) -> list[dict]:
    """One fresh interpreter: warm up ``method``, then time each size (``--child``)."""
    cmd = [
        sys.executable,
        __file__,
        "--child",
        method,
        kind,
        ",".join(map(str, sizes)),
        str(repeats),
        str(textures),
    ]
    cmd.append(str(budget))
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        print(done.stderr[-2000:], file=sys.stderr)
        return []
    return [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]


def _release_freed() -> None:
    """Give the memory the allocator keeps from freed arrays back to the system (glibc's
    ``malloc_trim``), so that the next run's resident growth counts every array it touches,
    not only those larger than what the warm-up and the previous runs freed."""
    import ctypes

    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def child_main(method: str, kind: str, sizes: str, repeats: str, textures: str, budget: str) -> int:
    import texsyn

    image = exemplar(Path(textures), kind)
    side = max(WARM_SIZE, 4 * texsyn.make_method(method).min_exemplar_size()[0])
    warm = image[:side, :side]
    if method == "sparse":  # its multiscale fit needs enough patches at every scale
        warm = image
    # numba and its code generator (about 130 MiB of resident memory once a first kernel is
    # loaded) belong to the libraries, not to the method (docs/memory.md, "Not counted"): a
    # method that loads them only from some size on (Heeger-Bergen's compiled ranks, cwt's
    # growth) would otherwise count them in that size's peak; loaded first, with the
    # compiled ranks, and the warm-up then loads the kernels the method uses
    import numba  # noqa: F401

    from texsyn.ops.histogram import match_sorted_rows

    match_sorted_rows(np.zeros((1, 2)), np.zeros((1, 2)))

    texsyn.make_method(method).fit(warm).sample((WARM_SIZE, WARM_SIZE), rng=0)
    for size in (int(s) for s in sizes.split(",")):
        walls, cpus, peaks = [], [], []
        for r in range(int(repeats)):
            _release_freed()
            base = status_kib("VmRSS")
            peak_reset()
            w0, c0 = time.perf_counter(), time.process_time()
            model = texsyn.make_method(method).fit(image)
            w1 = time.perf_counter()
            model.sample((size, size), rng=r)
            w2, c2 = time.perf_counter(), time.process_time()
            walls.append((w2 - w0, w2 - w1))
            cpus.append(c2 - c0)
            peaks.append(max(0, status_kib("VmHWM") - base) * 1024.0)
            if w2 - w0 > 10:
                break
        total = statistics.median(t for t, _ in walls)
        record = {
            "method": method,
            "kind": kind,
            "size": size,
            "runs": len(walls),
            "wall": total,
            "sample": statistics.median(s for _, s in walls),
            "cpu": statistics.median(cpus),
            "peak": statistics.median(peaks),
            "estimate": float(texsyn.make_method(method).estimate_memory(image.shape, (size, size))),
        }
        print(json.dumps(record), flush=True)
        if total > float(budget):
            break
    return 0


# ---------------------------------------------------------------------------- whole process
def process_case(method: str, kind: str, repeats: int, textures: Path, folder: Path) -> dict:
    import texsyn.io

    source = folder / f"exemplar_{kind}.png"
    if not source.exists():
        texsyn.io.write_image(source, exemplar(textures, kind))
    texsyn_exe = str(Path(sys.executable).with_name("texsyn"))
    cmd = [texsyn_exe, "synth", str(source), "-m", method, "--size", "256x256", "--seed", "0", "-q"]
    cmd += ["--overwrite", "-o", str(folder / "out.png")]
    time_process(cmd)  # numba's cache written by a first run is not what a user's run pays
    runs = [time_process(cmd) for _ in range(repeats)]
    return {
        "method": method,
        "kind": kind,
        "wall": statistics.median(r[0] for r in runs),
        "cpu": statistics.median(r[1] for r in runs),
        "peak": statistics.median(r[2] for r in runs),
        "runs": repeats,
    }


# ---------------------------------------------------------------------------- report
def mib(x: float) -> str:
    return f"{x / 2**20:.0f}"


def plot(records: list[dict], key: str, ylabel: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    for method in sorted({r["method"] for r in records}):
        rows = sorted((r["size"], r[key]) for r in records if r["method"] == method and r[key] > 0)
        if rows:
            ax.plot([s for s, _ in rows], [v for _, v in rows], marker="o", label=method)
    sizes = sorted({r["size"] for r in records})
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(sizes, [str(s) for s in sizes])
    ax.set_xlabel("output side (pixels), from a 128x128 colour exemplar")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def growth(records: list[dict], method: str, key: str) -> str:
    rows = sorted((r["size"], r[key]) for r in records if r["method"] == method)
    factors = [b / a for (_, a), (_, b) in zip(rows, rows[1:]) if a > 0]
    return ", ".join(f"{f:.1f}" for f in factors) if factors else ""


def main(argv: list[str] | None = None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        return child_main(*sys.argv[2:8])
    import texsyn

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--methods", nargs="*", default=list(texsyn.METHODS))
    p.add_argument("--skip-process", action="store_true")
    p.add_argument("--skip-scaling", action="store_true")
    p.add_argument("--scaling-sizes", type=int, nargs="*", default=[256, 512, 1024, 2048])
    p.add_argument(
        "--scaling-budget", type=float, default=60.0, help="stop a method's scaling after a run this long"
    )
    p.add_argument("--big", action="store_true", help="also quilting 8192x8192 to a PNG (streamed)")
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results.md")
    args = p.parse_args(argv)

    lines = [
        "# texsyn method timings and memory",
        "",
        machine() + f" Exemplar: top-left 128x128 of {EXEMPLAR}",
        "",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if not args.skip_process:
            lines += [
                "## Whole `texsyn synth` process, 128 -> 256 (issue 20's targets)",
                "",
                f"Median of {args.repeats} runs after one unmeasured run; CPU = user + system of every thread.",
                "",
                "| method | image | wall (s) | CPU (s) | peak RSS (MiB) | target (s) | met |",
                "|---|---|---:|---:|---:|---:|---|",
            ]
            for method in args.methods:
                for kind in ("grey", "colour"):
                    r = process_case(method, kind, args.repeats, args.textures, folder)
                    target = PROCESS_TARGETS.get((method, kind))
                    met = "" if target is None else ("yes" if r["wall"] <= target else "**no**")
                    tgt = "" if target is None else f"{target:g}"
                    lines.append(
                        f"| {method} | {kind} | {r['wall']:.2f} | {r['cpu']:.2f} | {mib(r['peak'])} | {tgt} | {met} |"
                    )
                    print(lines[-1], flush=True)
            lines.append("")

        lines += [
            "## In process, 128 -> 256 (after a warm-up: imports and compilation not counted)",
            "",
            "Peak = growth of the resident set over the warm-up; the estimate is `estimate_memory` "
            "(its margin: 1.05 where the terms were checked against measurements, 1.25 otherwise; "
            "`docs/memory.md`). GFLOP/s = the dominant arithmetic of the method's algorithm "
            "(`WORK` model in this script) over fit + sample.",
            "",
            "| method | image | fit + sample (s) | sample (s) | CPU (s) | peak (MiB) | estimate (MiB) | GFLOP/s | work counted |",
            "|---|---|---:|---:|---:|---:|---:|---:|---|",
        ]
        for method in args.methods:
            for kind in ("grey", "colour"):
                for r in run_child(method, kind, [256], args.repeats, args.textures, 1e9):
                    shape = (128, 128) if kind == "grey" else (128, 128, 3)
                    flops, what = work_model(method, shape, (256, 256))
                    rate = "" if math.isnan(flops) else f"{flops / r['wall'] / 1e9:.1f}"
                    lines.append(
                        f"| {method} | {kind} | {r['wall']:.3f} | {r['sample']:.3f} | {r['cpu']:.2f} | "
                        f"{mib(r['peak'])} | {mib(r['estimate'])} | {rate} | {what} |"
                    )
                    print(lines[-1], flush=True)
        lines.append("")

        if not args.skip_scaling:
            records: list[dict] = []
            for method in args.methods:
                got = run_child(method, "colour", args.scaling_sizes, 1, args.textures, args.scaling_budget)
                records += got
                print(method, [(r["size"], round(r["wall"], 2), mib(r["peak"])) for r in got], flush=True)
            plot(records, "wall", "fit + sample (s)", RESULTS / "time_vs_size.png")
            plot(records, "peak", "peak resident set growth (bytes)", RESULTS / "memory_vs_size.png")
            lines += [
                "## Scaling, 128 -> N colour, in process (one run per size)",
                "",
                "![time vs size](results/time_vs_size.png) ![memory vs size](results/memory_vs_size.png)",
                "",
                "Growth per doubling of the side: 4 is linear in the output's pixels.",
                "",
                "| method | "
                + " | ".join(f"{s} (s)" for s in args.scaling_sizes)
                + " | time growth | memory growth |",
                "|---|" + "---:|" * len(args.scaling_sizes) + "---|---|",
            ]
            for method in args.methods:
                by_size = {r["size"]: r for r in records if r["method"] == method}
                cells = [f"{by_size[s]['wall']:.2f}" if s in by_size else "" for s in args.scaling_sizes]
                lines.append(
                    f"| {method} | " + " | ".join(cells) + f" | {growth(records, method, 'wall')} | "
                    f"{growth(records, method, 'peak')} |"
                )
            lines.append("")

        if args.big:
            source = folder / "exemplar_colour.png"
            if not source.exists():
                texsyn.io.write_image(source, exemplar(args.textures, "colour"))
            texsyn_exe = str(Path(sys.executable).with_name("texsyn"))
            cmd = [
                texsyn_exe,
                "synth",
                str(source),
                "-m",
                "quilting",
                "--size",
                "8192x8192",
                "--seed",
                "0",
                "-q",
            ]
            wall, cpu, peak = time_process([*cmd, "-o", str(folder / "big.png")])
            lines += [
                "## 8192 x 8192 quilting to a PNG, whole process (streamed)",
                "",
                f"Wall {wall:.1f} s, CPU {cpu:.1f} s, peak RSS {mib(peak)} MiB (the float32 canvas alone "
                f"would be {8192 * 8192 * 3 * 4 / 2**20:.0f} MiB).",
                "",
            ]
            print(lines[-2], flush=True)

    write_report(args.out, lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
