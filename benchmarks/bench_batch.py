"""Batch runs on Dask: speed-up of 2 workers over 1, and the scheduler's overhead per task (issue 22).

Usage (real-time priority, as the other benchmarks, so that other work on a shared machine
does not take the cores the workers are timed on)::

    chrt -f 50 python benchmarks/bench_batch.py [--out benchmarks/results.md] [--repeats 3]

Three measurements, written as the section "Batch runs on Dask" of ``benchmarks/results.md``
(replaced in place when it is there, appended otherwise; ``bench_methods.py`` rewrites the
rest of that file):

* 32 small jobs (4 exemplars 64x64, quilting and heeger_bergen, 4 seeds each, 256x256
  outputs) with :func:`texsyn.batch.run` on a local cluster of 1, then 2 worker processes
  of one thread each. The cluster is started and warmed up first (one batch of the same
  methods in another folder: worker imports and numba's cache loads are not counted); the
  time is the batch's wall time, fits included, median of ``--repeats`` runs in new folders.
  The local cluster leaves out Dask's ``MALLOC_TRIM_THRESHOLD_`` (``docs/batch.md``); the
  cost of that setting is measured too, on the serial run.
  The same 32 jobs one after the other in this process, without Dask, give the serial
  baselines: with the process's threads, and with one thread as a worker has.
* The scheduler's overhead per task: 500 trivial tasks (``client.submit`` of a function that
  returns at once) on the 2-worker cluster, wall time / 500.
* The batch's overhead per item: 64 items of the cheapest kind (random phase, 8x8 exemplar,
  8x8 output), whose compute is about a millisecond: wall time / 64, which includes the
  manifest's ``fsync`` and the checksum.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import REPO, machine

import texsyn
import texsyn.batch as batch
from texsyn.batch.tasks import one_thread
from texsyn.io import write_image
from texsyn.ops.linalg import worker_count

METHODS = ["quilting", "heeger_bergen"]
PARAMS = {"quilting": {"patch_size": 24}}
SIZE = (256, 256)
SECTION = "## Batch runs on Dask (issue 22)"


def exemplars(folder: Path, side: int, count: int = 4) -> Path:
    """``count`` crops of the built-in textures, ``side`` pixels square, written to ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    sources = [texsyn.data.exemplar(name, size=None) for name in ("brick", "grass", "gravel")]
    for k in range(count):
        image = sources[k % 3][40 * k : 40 * k + side, 50 * k : 50 * k + side]
        write_image(folder / f"ex{k}.png", image)
    return folder


def noop(x):
    return x


def time_batch(client, root: Path, inputs: Path, repeats: int) -> float:
    """Median wall time of the 32-job batch on ``client``, each run in a new folder."""
    times = []
    for r in range(repeats):
        items = batch.plan([str(inputs)], root / f"run{r}", METHODS, seeds=4, size=SIZE, params=PARAMS)
        assert len(items) == 32
        start = time.perf_counter()
        records = batch.run(items, client)
        times.append(time.perf_counter() - start)
        assert all(rec["status"] == "done" for rec in records)
    return statistics.median(times)


def serial(inputs: Path, root: Path) -> float:
    """The 32 jobs in this process, one after the other: fit once per (exemplar, method), sample, write."""
    from texsyn.batch.synthesis import write_texture
    from texsyn.data import load_exemplar
    from texsyn.io import OutputSet
    from texsyn.ops.canvas import prepare_exemplar

    items = batch.plan([str(inputs)], root / "serial", METHODS, seeds=4, size=SIZE, params=PARAMS)
    start = time.perf_counter()
    fitted = {}
    for item in items:
        if item.fit_key not in fitted:
            exemplar = prepare_exemplar(load_exemplar(item.exemplar)[0])
            fitted[item.fit_key] = (texsyn.make_method(item.method, **item.params).fit(exemplar), exemplar)
        model, exemplar = fitted[item.fit_key]
        item.output_path.parent.mkdir(parents=True, exist_ok=True)
        outputs = OutputSet(overwrite=True)
        path = outputs.claim(item.output_path)
        write_texture(outputs, model, SIZE, item.seed, path, exemplar.shape)
    return time.perf_counter() - start


def serial_process(inputs: Path, root: Path, trim: bool) -> float:
    """:func:`serial` with one thread in a new process, with or without Dask's ``MALLOC_TRIM_THRESHOLD_``."""
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}
    if trim:
        env["MALLOC_TRIM_THRESHOLD_"] = "65536"
    args = [sys.executable, __file__, "--child-serial", str(inputs), str(root)]
    return float(subprocess.run(args, env=env, capture_output=True, text=True, check=True).stdout.split()[-1])


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--child-serial":
        inputs, root = Path(sys.argv[2]), Path(sys.argv[3])
        serial(inputs, root / "warm")
        with one_thread():
            print(min(serial(inputs, root / f"r{k}") for k in range(2)))
        return
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results.md")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        inputs = exemplars(root / "in", 64)
        tiny = exemplars(root / "tiny", 8)
        serial(inputs, root / "warm")  # imports and numba's cache in this process
        threads = worker_count()
        base = serial(inputs, root / "threads")
        plain = serial_process(inputs, root / "plain", trim=False)
        trimmed = serial_process(inputs, root / "trim", trim=True)
        with one_thread():
            alone = serial(inputs, root / "one")
        walls = {}
        for n in (1, 2):
            start = time.perf_counter()
            with batch.connect(workers=n) as client:
                started = time.perf_counter() - start
                warm = batch.plan(
                    [str(inputs)], root / f"warm{n}", METHODS, seeds=n, size=SIZE, params=PARAMS
                )
                batch.run(warm, client)
                walls[n] = (started, time_batch(client, root / f"w{n}", inputs, args.repeats))
                print(f"{n} worker(s): start {started:.2f} s, batch {walls[n][1]:.2f} s", flush=True)
                if n == 2:
                    client.gather(client.map(noop, range(50), pure=False))
                    start = time.perf_counter()
                    client.gather(client.map(noop, range(500), pure=False))
                    per_task = (time.perf_counter() - start) / 500
                    items = batch.plan(
                        [str(tiny)], root / "tiny-out", ["random_phase"], seeds=16, size=(8, 8)
                    )
                    batch.run(items[:4], client)  # warm
                    rest = items[4:] + batch.plan(
                        [str(tiny)],
                        root / "tiny-out",
                        ["random_phase"],
                        seed_list=range(100, 104),
                        size=(8, 8),
                    )
                    start = time.perf_counter()
                    batch.run(rest, client)
                    per_item = (time.perf_counter() - start) / len(rest)
                    n_tiny = len(rest)
    speedup = walls[1][1] / walls[2][1]
    section = [
        SECTION,
        "",
        machine(),
        "",
        "`benchmarks/bench_batch.py`: 32 jobs (4 exemplars 64x64 x quilting (patch 24) and "
        "heeger_bergen x 4 seeds, 256x256 outputs, fits included: one per exemplar and method) "
        f"on a local Dask cluster of worker processes with one thread each; median of {args.repeats} "
        "runs after a warm-up batch, every process at real-time priority (`chrt -f 50`) on the "
        "shared machine.",
        "",
        "| run | cluster start (s) | 32 jobs (s) | per job (s) | speed-up over 1 worker |",
        "|---|---:|---:|---:|---:|",
        f"| serial, in process, no Dask, {threads} threads | | {base:.2f} | {base / 32:.3f} | |",
        f"| serial, in process, no Dask, 1 thread | | {alone:.2f} | {alone / 32:.3f} | |",
        f"| serial, new process, 1 thread | | {plain:.2f} | {plain / 32:.3f} | |",
        f"| serial, new process, 1 thread, `MALLOC_TRIM_THRESHOLD_=65536` | | {trimmed:.2f} | "
        f"{trimmed / 32:.3f} | |",
        f"| 1 worker | {walls[1][0]:.2f} | {walls[1][1]:.2f} | {walls[1][1] / 32:.3f} | 1.00 |",
        f"| 2 workers | {walls[2][0]:.2f} | {walls[2][1]:.2f} | {walls[2][1] / 32:.3f} | {speedup:.2f} |",
        "",
        f"Scheduler overhead: {per_task * 1e3:.2f} ms per trivial task (500 tasks on 2 workers); "
        f"batch overhead: {per_item * 1e3:.1f} ms per item of {n_tiny} items whose compute is about "
        "a millisecond (random phase, 8x8), manifest `fsync` and checksum included.",
        "",
    ]
    text = args.out.read_text() if args.out.exists() else ""
    if SECTION in text:
        head, rest = text.split(SECTION, 1)
        tail = rest[rest.find("\n## ") + 1 :] if "\n## " in rest else ""
        text = head + "\n".join(section) + ("\n" + tail if tail else "")
    else:
        text = text.rstrip("\n") + "\n\n" + "\n".join(section)
    args.out.write_text(text)
    print("\n".join(section))


if __name__ == "__main__":
    main()
