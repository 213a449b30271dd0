"""Estimated against measured peak memory of every method (``docs/memory.md``).

Usage::

    python benchmarks/bench_memory.py [--out benchmarks/memory.md] [--quick | --defaults] [--only NAME ...]

Every configuration (method, parameters, exemplar, output size) runs in a fresh Python
process, after a small run of the same method (imports, Numba compilation, BLAS buffers and
the thread pool are then in place and not counted):

* untraced, fit then sample, reading the growth of the resident set: the high-water mark
  ``VmHWM`` of each step (reset before it through Linux's ``/proc/self/clear_refs``) minus
  the resident set before the fit (``RSS fit``, ``RSS sample``, the model included); a run
  that loads numba itself (a large one takes the compiled ranks, ``texsyn.ops.ranks``) is
  measured again with numba loaded, its import not being the run's (``docs/memory.md``);
* under ``tracemalloc``, which sees every NumPy array and Python object but not what
  compiled code allocates for itself (Numba arrays, k-d trees, FFT scratch): the peak of
  ``fit`` and the peak of ``sample`` (the fitted model included).

``--defaults`` runs every method at its default parameters on 128x128 grey and colour
exemplars, outputs 256x256 and 512x512 (use ``--out`` to keep ``benchmarks/memory.md``).

``modify`` rows run :func:`texsyn.modify`'s work (fit, then ``PatchWavelet.modify`` of a
texture of the given size, ratio 0.2); their estimate is ``estimate_modify_memory``.

The ratio columns divide the estimate by the larger measurement; ``docs/memory.md`` asks
for ratios between 1 and about 2 (an estimate below the measurement lets a process be
killed, one far above refuses work that would fit).
"""

from __future__ import annotations

import ctypes
import gc
import json
import os
import subprocess
import sys
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np

#: (method, parameters, exemplar side, colour, output (height, width))
CONFIGS = [
    ("quilting", {}, 128, True, (256, 256)),
    ("quilting", {}, 128, False, (1024, 1024)),
    ("efros_leung", {}, 64, False, (96, 96)),
    ("efros_leung", {}, 96, True, (112, 112)),
    ("heeger_bergen", {}, 128, True, (256, 256)),
    ("heeger_bergen", {}, 128, False, (768, 768)),
    ("random_phase", {}, 128, True, (512, 512)),
    ("random_phase", {}, 256, True, (1024, 1024)),
    ("lg", {}, 128, True, (256, 256)),
    ("lg", {}, 256, True, (512, 512)),
    ("clg", {}, 128, True, (256, 256)),
    ("rclg", {}, 128, False, (256, 256)),
    ("mslg", {}, 128, True, (256, 256)),
    ("mslg", {"n_scales": 3}, 256, True, (512, 512)),
    ("cwt", {}, 128, True, (512, 512)),
    ("cwt", {"refine": True}, 128, True, (256, 256)),
    ("wei_levoy", {"levels": 3}, 64, False, (96, 96)),
    ("wei_levoy", {"levels": 3}, 128, True, (128, 128)),
    ("sparse", {"n_outer": 2, "ksvd_iterations": 2}, 64, False, (128, 128)),
    ("sparse", {"n_outer": 2, "ksvd_iterations": 2}, 128, True, (256, 256)),
    ("patch_wavelet", {}, 64, True, (256, 256)),
    ("patch_wavelet", {}, 128, False, (512, 512)),
    ("grouplets", {"n_iterations": 5}, 128, True, (256, 256)),
    ("grouplets", {"n_iterations": 5}, 128, False, (512, 512)),
    ("portilla_simoncelli", {"n_iterations": 5}, 128, True, (256, 256)),
    ("portilla_simoncelli", {"n_iterations": 5}, 256, False, (512, 512)),
]
#: ``--defaults``: every method at its default parameters, 128x128 grey and colour exemplars,
#: 256x256 and 512x512 outputs (``benchmarks/memory.md``, issue 20's rounds)
DEFAULT_METHODS = [
    "efros_leung",
    "wei_levoy",
    "quilting",
    "heeger_bergen",
    "random_phase",
    "lg",
    "clg",
    "rclg",
    "mslg",
    "cwt",
    "patch_wavelet",
    "grouplets",
    "portilla_simoncelli",
    "sparse",
]
DEFAULT_CONFIGS = [
    (m, {}, 128, colour, (side, side))
    for m in DEFAULT_METHODS
    for colour in (False, True)
    for side in (256, 512)
]
#: configurations run through ``sample_rows`` (the rows consumed and dropped, as a writer would)
#: against ``estimate_memory(..., streaming=True)``
STREAMED_CONFIGS = [
    ("quilting", {}, 128, True, (2048, 2048)),
    ("quilting", {}, 128, False, (1024, 4096)),
    ("lg", {"histogram": "none"}, 128, True, (1024, 2048)),
    ("clg", {"histogram": "none"}, 128, False, (512, 4096)),
    ("rclg", {"histogram": "none"}, 128, True, (768, 1024)),
]
#: texsyn.modify's work: (exemplar side, colour, texture (height, width))
MODIFY_CONFIGS = [(64, True, (192, 192)), (64, True, (333, 77)), (128, False, (256, 256))]


def _exemplar(side: int, colour: bool) -> np.ndarray:
    """A crop of a built-in texture; colour ones mix three of them (like the tests' fixture)."""
    import texsyn

    if not colour:
        return texsyn.data.exemplar("gravel", size=side)
    layers = [texsyn.data.exemplar(name, size=side) for name in ("grass", "gravel", "brick")]
    mix = np.array([[0.5, 0.3, 0.2], [0.6, 0.3, 0.1], [0.2, 0.2, 0.6]])
    return (np.stack(layers, axis=-1) @ mix.T).astype(np.float32)


def _status_bytes(field: str) -> int:
    """``VmRSS`` (resident set) or ``VmHWM`` (its high-water mark) of this process, in bytes."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    raise RuntimeError(f"no {field} in /proc/self/status")  # pragma: no cover - not Linux


def _reset_peak() -> int:
    """Give freed heap memory back (``malloc_trim``), reset the high-water mark to the
    current resident set (Linux ``clear_refs``) and return it."""
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        pass
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:  # pragma: no cover - older kernels: the mark keeps earlier peaks
        pass
    return _status_bytes("VmRSS")


def measure(spec: dict) -> dict:
    """Run one configuration in this process; return estimates and measurements in bytes."""
    import texsyn
    from texsyn.ops import ranks
    from texsyn.ops.linalg import matmul

    warnings.simplefilter("ignore")
    name, params = spec["method"], spec["params"]
    exemplar = _exemplar(spec["side"], spec["colour"])
    shape = tuple(spec["shape"])
    modify = name == "modify"
    method_name = "patch_wavelet" if modify else name
    method = texsyn.make_method(method_name, **params)
    texture = texsyn.data.exemplar("gravel", size=None)[: shape[0], : shape[1]] if modify else None

    streaming = bool(spec.get("streaming"))

    def second_step(fitted):
        if streaming:
            for _ in fitted.sample_rows(shape, rng=0):
                pass
            return None
        return fitted.modify(texture, 0.2) if modify else fitted.sample(shape, rng=0)

    # warm-up: a small exemplar and an output larger than it, so that every code path runs,
    # the threaded rank kernels included (larger runs take them; compiling one when its cache
    # is stale holds about 12 MiB of resident memory for a moment, once per process)
    side = min(spec["side"], max(64, 2 * method.min_exemplar_size()[0]))
    threshold, ranks.PARALLEL_RANK_VALUES = ranks.PARALLEL_RANK_VALUES, 0
    small = texsyn.make_method(method_name, **params).fit(exemplar[:side, :side])
    small.modify(texture[:24, :24], 0.2) if modify else small.sample((2 * side + 8,) * 2, rng=0)
    ranks.PARALLEL_RANK_VALUES = threshold
    del small
    matmul(np.ones((1024, 512)), np.ones((512, 1024)))  # BLAS buffers, the product thread pool

    fit_estimate = method.estimate_memory(exemplar.shape)
    if modify:
        run_estimate = method.estimate_modify_memory(exemplar.shape, texture.shape)
    else:
        run_estimate = method.estimate_memory(exemplar.shape, shape, streaming=streaming)

    # 1. untraced: growth of the resident set over its level before the fit
    def untraced() -> tuple[int, int, float]:
        before = _reset_peak()
        start = time.perf_counter()
        fitted = texsyn.make_method(method_name, **params).fit(exemplar)
        rss_fit = max(0, _status_bytes("VmHWM") - before)
        _reset_peak()
        second_step(fitted)
        seconds = time.perf_counter() - start
        rss_run = max(0, _status_bytes("VmHWM") - before)  # the fitted model is resident
        return rss_fit, rss_run, seconds

    numba_loaded = "numba" in sys.modules
    rss_fit, rss_run, seconds = untraced()
    if not numba_loaded and "numba" in sys.modules:
        # a large run loads numba for the compiled ranks (texsyn.ops.ranks.compiled_ranks),
        # which the warm-up's small run does not: about 130 MiB of resident memory that is
        # the import's, not the run's (docs/memory.md, "Not counted"); measured again with
        # numba loaded (the same kernels: the size chose them)
        rss_fit, rss_run, seconds = untraced()
    # 2. traced: peak of the fit, then of the second step (the fitted model included)
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    fitted = texsyn.make_method(method_name, **params).fit(exemplar)
    fit_peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.reset_peak()
    second_step(fitted)
    run_peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    return {
        **spec,
        "fit_estimate": fit_estimate,
        "run_estimate": run_estimate,
        "fit_traced": fit_peak,
        "run_traced": run_peak,
        "rss_fit": rss_fit,
        "rss_run": rss_run,
        "seconds": seconds,
    }


def _mib(n: float) -> str:
    return f"{n / 2**20:.1f}"


HEADER = [
    "| method | parameters | exemplar | output | fit estimate | fit traced | RSS fit | fit ratio "
    "| sample estimate | sample traced | RSS sample | sample ratio | peak ratio | seconds |",
    "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
]


def row(r: dict) -> str:
    """One markdown row (MiB).

    ``fit ratio``: fit estimate over the larger fit measurement; ``sample ratio``: sample
    estimate over the traced sample peak; ``peak ratio``: the larger estimate over the
    largest measurement (the RSS of the sampling step also holds what the allocator kept
    from the fit).
    """
    params = ", ".join(f"{k}={v}" for k, v in r["params"].items()) or "defaults"
    if r.get("streaming"):
        params += " (streamed rows)"
    ex = f"{r['side']}x{r['side']}{'x3' if r['colour'] else ''}"
    out = f"{r['shape'][1]}x{r['shape'][0]}"
    fit_measured = max(r["fit_traced"], r["rss_fit"])
    peak = max(fit_measured, r["run_traced"], r["rss_run"])
    peak_estimate = max(r["fit_estimate"], r["run_estimate"])
    return (
        f"| {r['method']} | {params} | {ex} | {out} | {_mib(r['fit_estimate'])} | {_mib(r['fit_traced'])} "
        f"| {_mib(r['rss_fit'])} | {r['fit_estimate'] / max(fit_measured, 1):.2f} | {_mib(r['run_estimate'])} "
        f"| {_mib(r['run_traced'])} | {_mib(r['rss_run'])} | {r['run_estimate'] / max(r['run_traced'], 1):.2f} "
        f"| {peak_estimate / max(peak, 1):.2f} | {r['seconds']:.1f} |"
    )


def main(argv: list[str] | None = None) -> int:
    from _common import machine, parser

    p = parser(__doc__.splitlines()[0], "memory.md", repeats=1)
    p.add_argument("--worker", help=argparse_suppress())
    p.add_argument(
        "--only", nargs="*", default=None, help="method names to run ('modify' for the modification)"
    )
    p.add_argument("--quick", action="store_true", help="only the first configuration of each method")
    p.add_argument(
        "--defaults",
        action="store_true",
        help="default parameters, 128x128 grey and colour exemplars, 256x256 and 512x512 outputs",
    )
    args = p.parse_args(argv)
    if args.worker:
        print(json.dumps(measure(json.loads(args.worker))))
        return 0
    specs = [
        {"method": m, "params": prm, "side": side, "colour": colour, "shape": list(shape)}
        for m, prm, side, colour, shape in (DEFAULT_CONFIGS if args.defaults else CONFIGS)
    ]
    if not args.defaults:
        specs += [
            {
                "method": m,
                "params": prm,
                "side": side,
                "colour": colour,
                "shape": list(shape),
                "streaming": True,
            }
            for m, prm, side, colour, shape in STREAMED_CONFIGS
        ]
        specs += [
            {"method": "modify", "params": {}, "side": side, "colour": colour, "shape": list(shape)}
            for side, colour, shape in MODIFY_CONFIGS
        ]
    if args.only:
        specs = [s for s in specs if s["method"] in args.only]
    if args.quick:
        seen: set[str] = set()
        specs = [s for s in specs if not (s["method"] in seen or seen.add(s["method"]))]
    print(machine())
    print("\n".join(HEADER), flush=True)
    rows = []
    # the workers run in benchmarks/: a relative PYTHONPATH (PYTHONPATH=src) is made absolute,
    # or they would import the installed texsyn instead of this checkout's
    paths = os.environ.get("PYTHONPATH", "").split(os.pathsep)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(str(Path(x).resolve()) for x in paths if x)}
    for spec in specs:
        done = subprocess.run(
            [sys.executable, __file__, "--worker", json.dumps(spec)],
            capture_output=True,
            text=True,
            cwd=Path(__file__).parent,
            env=env,
        )
        if done.returncode != 0:
            lines = done.stderr.strip().splitlines() or ["no output"]
            rows.append(f"| {spec['method']} | failed: {lines[-1]} |")
        else:
            rows.append(row(json.loads(done.stdout.strip().splitlines()[-1])))
        print(rows[-1], flush=True)
    text = "\n".join(["# Memory: estimate against measurement (MiB)", "", machine(), "", *HEADER, *rows, ""])
    args.out.write_text(text)
    return 0


def argparse_suppress():
    import argparse

    return argparse.SUPPRESS


if __name__ == "__main__":
    sys.exit(main())
