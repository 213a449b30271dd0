"""What every benchmark script shares: paths, the machine line, the common options."""

from __future__ import annotations

import argparse
import os
import platform
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
