"""The steps every command shares: inputs, outputs, the memory check, the seed, the sidecar.

A command checks all its outputs before any work (:func:`output_set`), refuses work too
large for memory from the exemplar's header before decoding it
(:func:`check_memory_before_reading`, ``docs/memory.md``), and writes beside its main output
a JSON sidecar that says how to make it again (:func:`sidecar`).
"""

from __future__ import annotations

import json
import math
import os
import secrets
import shlex
import sys
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import click
import numpy as np

from .._version import __version__
from ..batch.synthesis import input_path
from ..data import load_exemplar
from ..errors import InputError
from ..io import OutputSet, check_image_size, max_image_pixels, read_image, read_image_header
from ..io.arrays import load_npy
from ..io.writing import ARRAY_FORMATS, WRITE_FORMATS
from ..ops.canvas import default_output_shape, prepared_exemplar_shape
from .options import BUILTIN_PREFIX

__all__ = [
    "State",
    "check_memory_before_reading",
    "claim_extra",
    "command_line",
    "done",
    "draw_seed",
    "input_path",
    "jsonable",
    "load_exemplar",
    "output_set",
    "planned_shape",
    "read_flow",
    "sidecar_json",
    "stage_extra",
]


@dataclass
class State:
    """What :func:`texsyn.cli.main` knows about this run: the arguments and whether to show tracebacks."""

    debug: bool = False
    argv: list[str] = field(default_factory=list)
    #: ``"bar"`` (a rich bar) or ``"json"`` (one JSON object per line, for programs such as
    #: ``texsyn serve``), from ``texsyn --progress``
    progress: str = "bar"


# ---------------------------------------------------------------------------- inputs
def read_flow(path: str) -> np.ndarray:
    """A flow field from a .npy array (H, W, 2) or from the red/green channels of an image."""
    if Path(path).suffix.lower() == ".npy":
        flow = load_npy(path, "a flow array")  # header first: no pickle, no bomb, no pipe
        if flow.ndim != 3 or flow.shape[2] != 2 or flow.dtype.kind not in "iuf":
            raise InputError(
                f"flow array '{path}' must be real numbers of shape (H, W, 2), got {flow.dtype} {flow.shape}"
            )
        flow = flow.astype(np.float64)
        if not np.all(np.isfinite(flow)):
            raise InputError(f"flow array '{path}' holds NaN or infinite values")
        return flow
    picture = read_image(path)
    if picture.ndim != 3:
        raise InputError(f"flow image '{path}' must be a colour image (red = row, green = column component)")
    return 2.0 * picture[..., :2].astype(np.float64) - 1.0


def planned_shape(exemplar: str | None) -> tuple[int, ...] | None:
    """The exemplar's array shape from an image file's header, before any pixel is decoded
    (``None`` for a built-in exemplar); ``TEXSYN_MAX_PIXELS`` is validated either way."""
    max_image_pixels()
    if exemplar is None or exemplar.startswith(BUILTIN_PREFIX):
        return None
    header = read_image_header(exemplar)
    check_image_size(header, exemplar, file_size=os.path.getsize(exemplar))  # the file's own limits first
    return (header.height, header.width) + ((3,) if header.channels >= 3 else ())


def check_memory_before_reading(
    method,
    exemplar: str | None,
    output_shape=None,
    scale=None,
    *,
    streaming: bool = False,
    preparation: dict | None = None,
) -> None:
    """Refuse work over ``TEXSYN_MEMORY_LIMIT`` from the file's header, before decoding it
    (``docs/memory.md``); ``scale`` derives the output shape from the exemplar's, and
    without either the output has the default shape (twice the exemplar). ``streaming``:
    the output is written band by band (:meth:`~texsyn.methods.TextureSynthesizer.sample_rows`);
    ``preparation``: the keywords of :func:`~texsyn.ops.canvas.prepare_exemplar` applied after reading."""
    planned = planned_shape(exemplar)
    if planned is None:
        return
    if preparation:
        planned = prepared_exemplar_shape(planned, **preparation)
    if output_shape is None and scale is None:
        output_shape = default_output_shape(planned)
    elif output_shape is None:
        factor = float(scale)
        output_shape = (max(1, round(planned[0] * factor)), max(1, round(planned[1] * factor)))
    method.check_memory_for(planned, output_shape, streaming=streaming)


def draw_seed(seed: int | None) -> tuple[int, bool]:
    """The seed to use and whether it was drawn (no ``--seed``): from the OS, not global state."""
    if seed is not None:
        return int(seed), False
    return secrets.randbelow(2**32), True


# ---------------------------------------------------------------------------- outputs
def output_set(overwrite: bool) -> OutputSet:
    """The command's :class:`~texsyn.io.OutputSet` (errors suggest ``--overwrite``)."""
    return OutputSet(overwrite=overwrite, overwrite_hint="--overwrite")


def claim_extra(outputs: OutputSet, path: str | None, what: str) -> Path | None:
    """Claim an extra output written as a ``.npy`` array or as a picture (PNG/JPEG/TIFF)."""
    if path is None:
        return None
    return outputs.claim(path, formats={**WRITE_FORMATS, **ARRAY_FORMATS}, what=what)


def stage_extra(outputs: OutputSet, path: Path | None, array: np.ndarray, picture) -> None:
    """Stage ``array`` to a ``.npy`` path, or ``picture(array)`` (values in [0, 1]) to an image path."""
    if path is None:
        return
    if path.suffix.lower() == ".npy":
        outputs.write_array(path, array)
    else:
        outputs.write_image(path, picture(array))


def jsonable(value):
    """``value`` with NumPy arrays (as nested lists), scalars, tuples and non-finite floats made JSON-ready."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return str(value)


def command_line() -> str:
    """The command line of this run, quoted for a shell."""
    ctx = click.get_current_context(silent=True)
    state = ctx.find_object(State) if ctx is not None else None
    argv = state.argv if state is not None else sys.argv[1:]
    return shlex.join(["texsyn", *argv])


def sidecar_json(
    command: str,
    *,
    outputs: dict,
    inputs: dict,
    method: str,
    params: dict,
    seed,
    options: dict,
    diagnostics: dict | None = None,
) -> str:
    """The JSON written beside a command's main output: enough to know and redo what made it.

    ``diagnostics`` (:attr:`texsyn.methods.SynthesisResult.diagnostics`, what the method
    measured during the run) is written with its arrays as lists; ``null`` when it measured
    nothing.
    """
    record = {
        "texsyn_sidecar": 1,
        "texsyn_version": __version__,
        "command": command,
        "command_line": command_line(),
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "inputs": {k: v for k, v in inputs.items() if v is not None},
        "outputs": {k: str(v) for k, v in outputs.items() if v is not None},
        "method": method,
        "params": params,
        "seed": seed,
        "options": options,
        "diagnostics": diagnostics,
    }
    return json.dumps(jsonable(record), indent=2) + "\n"


def done(quiet: bool, seed: int | None, drawn: bool, line: str) -> None:
    """The closing message on stderr (the seed first when it was drawn), unless ``quiet``."""
    if quiet:
        return
    if drawn:
        click.echo(f"seed: {seed}", err=True)
    click.echo(line, err=True)
