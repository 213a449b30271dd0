"""What a batch worker runs: fit one (exemplar, method), make one item (``docs/batch.md``).

Both tasks are plain functions of picklable arguments, so that any Dask worker with texsyn
installed runs them. :func:`fit_task` reads the exemplar (a path on a shared file system, or
its bytes when there is none) exactly as ``texsyn synth`` does and returns the fitted model,
which Dask keeps on the worker and hands to every :func:`item_task` of that exemplar and
method. :func:`item_task` samples and writes the item's file (:func:`~texsyn.batch.synthesis.write_texture`,
the same bytes as ``synth``), and returns its record: checksum, time, peak memory, metrics
when asked, or the error. A failure of the item's own (a bad parameter, too little memory)
is recorded, not raised, so that Dask does not retry it; a worker that dies is Dask's to
handle (its tasks run again elsewhere).

Every task runs with one thread (:func:`one_thread`): BLAS, OpenMP, numba and texsyn's own
pool, so that N workers on N cores do not fight over them.
"""

from __future__ import annotations

import os
import socket
import sys
import tempfile
import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from .._version import __version__
from ..errors import InputError
from ..io import OutputSet, read_image
from ..io.reading import ImageFile
from ..methods import TextureSynthesizer, make_method
from ..ops.canvas import default_output_shape, prepare_exemplar
from ..ops.linalg import THREADS_VARIABLE
from .items import BatchItem, file_sha256
from .synthesis import read_batch_exemplar, write_texture

__all__ = [
    "ExemplarBytes",
    "FitError",
    "FitFailure",
    "FittedModel",
    "ONE_THREAD_ENVIRONMENT",
    "describe_error",
    "fit_task",
    "item_task",
    "one_thread",
    "peak_memory",
    "reset_peak_memory",
]

#: the environment of a worker process that runs one thread (set by the local cluster before it starts)
ONE_THREAD_ENVIRONMENT = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
    THREADS_VARIABLE: "1",
}


@dataclass(frozen=True)
class ExemplarBytes:
    """An exemplar file sent as bytes, for workers that do not see the client's files."""

    name: str
    data: bytes


@dataclass
class FittedModel:
    """What :func:`fit_task` returns: the fitted method, the exemplar it saw, the fit's seconds."""

    synthesizer: TextureSynthesizer
    exemplar: np.ndarray
    seconds: float
    #: the exemplar file's bit depth (8 or 16) and ICC profile: the output's, as ``synth`` writes it
    bit_depth: int = 8
    icc_profile: bytes | None = None


@dataclass(frozen=True)
class FitFailure:
    """A fit that failed: each of its items records ``error``."""

    error: str


@contextmanager
def one_thread():
    """Run the block with one thread: BLAS and OpenMP (threadpoolctl), numba, texsyn's own pool.

    ``NUMBA_NUM_THREADS`` is set only while numba is not loaded (numba refuses a change of
    it once its threads run); a loaded numba gets :func:`numba.set_num_threads` instead.
    """
    from threadpoolctl import threadpool_limits

    os.environ[THREADS_VARIABLE] = "1"
    numba = sys.modules.get("numba")
    if numba is None:
        os.environ["NUMBA_NUM_THREADS"] = "1"
    else:
        numba.set_num_threads(1)
    with threadpool_limits(limits=1):
        yield


def reset_peak_memory() -> bool:
    """Start a new peak of this process's resident memory (Linux: ``/proc/self/clear_refs``).

    Returns whether it could; if not, :func:`peak_memory` is the peak since the process started.
    """
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_memory() -> int:
    """The peak resident memory of this process in bytes, since :func:`reset_peak_memory`.

    Measured by the system (``VmHWM``), so it counts everything the item used (NumPy, numba,
    the encoders) at no cost to the item, and the process's own baseline (the interpreter, the
    fitted model) as well.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows: not measured
        return 0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)  # bytes on macOS, KiB elsewhere


def describe_error(exc: BaseException) -> str:
    """One line for a failed item: the exception's type and message."""
    message = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {message}" if message else type(exc).__name__


def _read_source(source: str | ExemplarBytes) -> ImageFile:
    if isinstance(source, ExemplarBytes):  # written where the reader can open it, as the client's file
        with tempfile.TemporaryDirectory(prefix="texsyn-batch-") as folder:
            path = Path(folder) / ("exemplar" + Path(source.name).suffix)
            path.write_bytes(source.data)
            return read_batch_exemplar(path, source.name)
    return read_batch_exemplar(source)


def fit_task(source: str | ExemplarBytes, method: str, params: dict) -> FittedModel | FitFailure:
    """Read the exemplar as ``synth`` does and fit ``method`` with ``params`` (the ``-p`` values)."""
    try:
        with one_thread():
            start = time.perf_counter()
            found = _read_source(source)
            exemplar = prepare_exemplar(found.pixels)
            synthesizer = make_method(method, **params)
            synthesizer.fit(exemplar)
            depth = 16 if found.bit_depth == 16 else 8
            return FittedModel(synthesizer, exemplar, time.perf_counter() - start, depth, found.icc_profile)
    except Exception as exc:  # recorded by each of its items
        return FitFailure(describe_error(exc))


def item_task(
    item: BatchItem,
    fitted: FittedModel | FitFailure,
    *,
    send_bytes: bool = False,
    overwrite: bool = False,
    metrics: bool = False,
) -> dict:
    """Make one item's file and return its manifest record.

    Parameters
    ----------
    item : BatchItem
    fitted : FittedModel or FitFailure
        What :func:`fit_task` returned for the item's exemplar and method.
    send_bytes : bool
        Write the file in a temporary folder of the worker and return its bytes (under the
        key ``"data"``) for the client to write; otherwise write it at ``item.output_path``.
    overwrite : bool
        Replace an existing output. Without it an existing output is kept if it is what the
        item makes (the same checksum: an earlier run wrote it and stopped before recording
        it), and the item fails otherwise.
    metrics : bool
        Measure the output (:func:`texsyn.metrics.evaluate`, on the file as written).
    """
    record: dict = {
        **item.to_dict(),
        "texsyn_version": __version__,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }
    start = time.perf_counter()
    record["peak_memory_scope"] = "item" if reset_peak_memory() else "process"
    try:
        if isinstance(fitted, FitFailure):
            raise FitError(fitted.error)
        record["fit_seconds"] = fitted.seconds
        with one_thread(), ExitStack() as stack:
            target = item.output_path
            if send_bytes:  # made in a scratch folder of the worker, sent back as bytes
                scratch = stack.enter_context(tempfile.TemporaryDirectory(prefix="texsyn-batch-"))
                target = Path(scratch) / target.name
            else:  # the exemplar's folder, made by the first of its items that gets this far
                target.parent.mkdir(parents=True, exist_ok=True)
                if target.exists() and not overwrite:  # made beside it, then compared
                    target = target.parent / f".{target.name}.{os.getpid()}.check.png"
                    stack.callback(target.unlink, missing_ok=True)
            shape = _make(item, fitted, target)
            digest = file_sha256(target)
            record["size"] = [shape[1], shape[0]]
            record["seconds"] = time.perf_counter() - start
            if metrics:
                measuring = time.perf_counter()
                record["metrics"] = _measure(target, fitted.exemplar)
                record["metrics_seconds"] = time.perf_counter() - measuring
            if send_bytes:
                record["data"] = target.read_bytes()
            elif target != item.output_path:  # the output existed: kept only if it is this item's
                if file_sha256(item.output_path) != digest:
                    raise InputError(
                        f"output '{item.output_path}' exists and is not what this item makes; "
                        "--overwrite replaces it"
                    )
                record["adopted"] = True
        record.update(status="done", sha256=digest, error=None)
    except FitError as exc:
        record.update(status="failed", sha256=None, error=f"fit failed: {exc}")
    except Exception as exc:
        record.update(status="failed", sha256=None, error=describe_error(exc))
    record["peak_memory_bytes"] = peak_memory()
    record.setdefault("seconds", time.perf_counter() - start)
    record["finished"] = datetime.now(UTC).isoformat(timespec="seconds")
    return record


class FitError(Exception):
    """The fit of the item's exemplar and method failed; the message is the fit's error."""


def _make(item: BatchItem, fitted: FittedModel, target: Path) -> tuple[int, int]:
    """Sample the item and write it to ``target`` (all or nothing); the output's (height, width)."""
    synthesizer = fitted.synthesizer
    exemplar = fitted.exemplar
    shape = item.size if item.size is not None else default_output_shape(exemplar.shape)
    synthesizer.check_memory_for(exemplar.shape, shape, streaming=synthesizer.streams_rows)
    outputs = OutputSet(overwrite=True)
    path = outputs.claim(target, bit_depth=fitted.bit_depth)
    write_texture(
        outputs,
        synthesizer,
        shape,
        item.seed,
        path,
        exemplar.shape,
        bit_depth=fitted.bit_depth,
        icc_profile=fitted.icc_profile,
    )
    return shape


def _measure(path: Path, exemplar: np.ndarray) -> dict[str, float]:
    from ..metrics import evaluate

    image = read_image(path).astype(np.float64)
    return {k: float(v) for k, v in evaluate(image, exemplar).items()}
