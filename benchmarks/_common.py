"""What every benchmark script shares: paths, the machine line, the common options."""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

import texsyn

REPO = Path(__file__).resolve().parents[1]
DEFAULT_TEXTURES = REPO.parent / "shared" / "textures"
RESULTS = REPO / "benchmarks" / "results"


def machine() -> str:
    """One line naming the machine and the library versions, for the tables' headers."""
    return (
        f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
        f"numpy {np.__version__}, texsyn {texsyn.__version__}."
    )


def parser(description: str, report: str, repeats: int = 2) -> argparse.ArgumentParser:
    """Options ``--textures``, ``--repeats``, ``--out`` (``benchmarks/<report>``) and ``--images``."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--textures", type=Path, default=DEFAULT_TEXTURES)
    p.add_argument("--repeats", type=int, default=repeats)
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / report)
    p.add_argument("--images", type=Path, default=RESULTS)
    return p


def peak_reset() -> None:
    """Reset this process's resident high-water mark (``VmHWM``; Linux ``/proc/self/clear_refs``)."""
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")


def status_kib(field: str) -> int:
    """A field of ``/proc/self/status`` in KiB (``VmRSS``, ``VmHWM``), 0 when absent."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def time_process(args: list[str]) -> tuple[float, float, float]:
    """Wall, CPU (user + system, all threads) and peak RSS (bytes) of one child process."""
    start = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(
            f"{' '.join(args)} failed: {proc.stderr.read().decode()[-500:] if proc.stderr else ''}"
        )
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss * 1024.0


def write_report(path: Path, lines: list[str]) -> None:
    """Write a report's markdown lines to ``path`` (its folder made) and say where."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    print(f"\nwrote {path}")
