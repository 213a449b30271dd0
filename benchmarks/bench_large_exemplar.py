"""Fit cost and memory of a phone-photo-sized exemplar (4000x3000), and the documented way out.

Usage::

    python benchmarks/bench_large_exemplar.py [--methods NAME ...] [--max-side 512]
                                              [--out benchmarks/results/large_exemplar.md]

Issue 20, item 4: exemplars as large as a phone photo are accepted, their fit cost and memory
measured, with a documented option to downscale or crop (``docs/performance.md``, "Large
exemplars"). The photo is made once: a 4000x3000 colour texture quilted from Brick-00 (the
shared textures hold no photo that large; quilting gives one with real texture content), saved
as a PNG in a temporary folder.

For every method, in a fresh process each:

1. **the whole photo**: ``estimate_memory`` of its fit; when the estimate is within
   ``TEXSYN_MEMORY_LIMIT`` (half the machine's memory by default), ``fit`` is timed in process
   (wall, CPU of every thread, growth of the resident set over the process's level after
   the imports and the reading of the photo); otherwise the row says it is refused before any
   work, as the command line does;
2. **the documented option**: the whole command ``texsyn synth photo.png -m METHOD
   --exemplar-max-side 512 --size 512x512`` (wall, CPU, peak resident set of the process:
   the photo's decoding included).

Timings belong here, not in the test suite.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import DEFAULT_TEXTURES, RESULTS, machine, peak_reset, status_kib, time_process, write_report

PHOTO_SHAPE = (3000, 4000)  # height, width: a 12-megapixel phone photo
SOURCE = "gh_tartavel_vistex/Brick-00.png"


def make_photo(textures: Path, path: Path) -> None:
    """A 4000x3000 colour texture quilted from Brick-00, written to ``path``."""
    import texsyn
    import texsyn.io

    exemplar = texsyn.io.read_image(textures / SOURCE)
    photo = texsyn.synthesize(exemplar, "quilting", PHOTO_SHAPE, rng=0)
    texsyn.io.write_image(path, photo)


def child_fit(method: str, photo: str) -> int:
    """Fit ``method`` on the photo in this process; print one JSON line."""
    import texsyn
    import texsyn.io
    from texsyn._validation import memory_limit_bytes

    image = texsyn.io.read_image(photo)
    model = texsyn.make_method(method)
    estimate = float(model.estimate_memory(image.shape))
    record: dict = {"method": method, "estimate": estimate, "limit": float(memory_limit_bytes())}
    if estimate > record["limit"]:
        record["refused"] = True
    else:
        base = status_kib("VmRSS")
        peak_reset()
        w0, c0 = time.perf_counter(), time.process_time()
        model.fit(image)
        record["wall"] = time.perf_counter() - w0
        record["cpu"] = time.process_time() - c0
        record["peak"] = max(0, status_kib("VmHWM") - base) * 1024.0
    print(json.dumps(record), flush=True)
    return 0


def mib(x: float) -> str:
    return f"{x / 2**20:,.0f}"


def main(argv: list[str] | None = None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        return child_fit(sys.argv[2], sys.argv[3])
    import texsyn

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    p.add_argument("--methods", nargs="*", default=list(texsyn.METHODS))
    p.add_argument("--max-side", type=int, default=512)
    p.add_argument("--out", type=Path, default=RESULTS / "large_exemplar.md")
    args = p.parse_args(argv)

    lines = [
        "## A 4000x3000 colour exemplar (a phone photo's size)",
        "",
        machine(),
        "",
        f"Fit of the whole photo in process, and the whole command `texsyn synth photo.png -m METHOD "
        f"--exemplar-max-side {args.max_side} --size 512x512` (`benchmarks/bench_large_exemplar.py`).",
        "",
        "| method | fit estimate (MiB) | fit: wall (s) | fit: CPU (s) | fit: peak growth (MiB) | "
        f"`--exemplar-max-side {args.max_side}`: wall (s) | CPU (s) | peak RSS (MiB) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        photo = Path(tmp) / "photo.png"
        make_photo(args.textures, photo)
        texsyn_exe = str(Path(sys.executable).with_name("texsyn"))
        for method in args.methods:
            done = subprocess.run(
                [sys.executable, __file__, "--child", method, str(photo)],
                capture_output=True,
                text=True,
                check=False,
            )
            rows = [json.loads(x) for x in done.stdout.splitlines() if x.startswith("{")]
            if not rows:
                fit_cells = ["failed: " + done.stderr.strip().splitlines()[-1][:80], "", "", ""]
            elif rows[0].get("refused"):
                r = rows[0]
                fit_cells = [mib(r["estimate"]), f"refused (limit {mib(r['limit'])} MiB)", "", ""]
            else:
                r = rows[0]
                fit_cells = [mib(r["estimate"]), f"{r['wall']:.2f}", f"{r['cpu']:.2f}", mib(r["peak"])]
            cmd = [texsyn_exe, "synth", str(photo), "-m", method, "--size", "512x512", "--seed", "0"]
            cmd += ["-q", "--exemplar-max-side", str(args.max_side), "--overwrite"]
            cmd += ["-o", str(Path(tmp) / "out.png")]
            wall, cpu, peak = time_process(cmd)
            lines.append(
                f"| {method} | " + " | ".join(fit_cells) + f" | {wall:.2f} | {cpu:.2f} | {mib(peak)} |"
            )
            print(lines[-1], flush=True)
    write_report(args.out, lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
