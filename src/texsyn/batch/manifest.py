"""The batch's manifest: one JSON line per finished or failed item, the record a rerun trusts.

``OUTDIR/manifest.jsonl`` (``docs/batch.md``, "Manifest"). Only the process that runs the
batch writes it: each record is one ``write`` of one line to the file opened for appending,
followed by ``fsync``, so a crash leaves at most a last line cut short, which
:meth:`Manifest.read` skips. A later record of an item replaces an earlier one. The folder is
locked while a batch runs (``OUTDIR/.texsyn-batch.lock``) so that two batches never write
the same manifest and outputs at once.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

from ..errors import InputError
from .items import BatchItem, file_sha256

__all__ = ["MANIFEST_NAME", "Manifest", "verified"]

MANIFEST_NAME = "manifest.jsonl"
LOCK_NAME = ".texsyn-batch.lock"


class Manifest:
    """The manifest of the batch writing into ``outdir``; use as a context manager to lock it.

    Parameters
    ----------
    outdir : path
        The batch's output folder (created if missing).
    """

    def __init__(self, outdir: str | os.PathLike):
        self.outdir = Path(outdir)
        self.path = self.outdir / MANIFEST_NAME
        self._fd: int | None = None
        self._lock_fd: int | None = None
        self.skipped_lines = 0

    # -------------------------------------------------------------- reading
    def read(self) -> dict[str, dict]:
        """The last record of every item (by ``id``); lines that do not parse are counted and skipped."""
        records: dict[str, dict] = {}
        self.skipped_lines = 0
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return records
        for line in text.splitlines():
            if not line.strip():
                continue
            try:
                record = json.loads(line)
                records[record["id"]] = record
            except (ValueError, KeyError, TypeError):  # a line cut short by a crash
                self.skipped_lines += 1
        return records

    # -------------------------------------------------------------- writing
    def __enter__(self) -> Manifest:
        try:
            self.outdir.mkdir(parents=True, exist_ok=True)
        except (FileExistsError, NotADirectoryError):  # OUTDIR, or a folder above it, is a file
            raise InputError(
                f"output folder '{self.outdir}' cannot be made: it or a folder above it is a file; give a folder (-o)"
            ) from None
        self._lock()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def append(self, record: dict) -> None:
        """Add one record as one line, on disk (``fsync``) before returning.

        The file is opened (made if missing) at the first record, so a batch that makes
        nothing leaves none.
        """
        if self._lock_fd is None:
            raise RuntimeError("the manifest is not open for writing (use it as a context manager)")
        if self._fd is None:
            self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
            size = os.fstat(self._fd).st_size
            if size:
                with open(self.path, "rb") as f:
                    f.seek(size - 1)
                    if f.read(1) != b"\n":  # a last line cut short: end it, so the next record parses
                        os.write(self._fd, b"\n")
        line = (json.dumps(_finite(record), sort_keys=True, allow_nan=False) + "\n").encode("utf-8")
        written = 0
        while written < len(line):  # a regular file takes it in one write, barring a full disk
            written += os.write(self._fd, line[written:])
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing the descriptor releases the lock
            self._lock_fd = None

    def _lock(self) -> None:
        fd = os.open(self.outdir / LOCK_NAME, os.O_WRONLY | os.O_CREAT, 0o666)
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: the file is held open, not locked
            self._lock_fd = fd
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise InputError(
                f"another texsyn batch is writing to '{self.outdir}'; wait for it or choose another output folder"
            ) from None
        self._lock_fd = fd


def _finite(value):
    """``value`` with NaN and infinite floats as ``None`` (strict JSON has no such numbers)."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def verified(item: BatchItem, record: dict | None) -> bool:
    """Whether ``record`` says ``item`` is done and its output file still has the recorded checksum."""
    if record is None or record.get("status") != "done" or record.get("output") != item.output:
        return False
    try:
        return file_sha256(item.output_path) == record.get("sha256")
    except OSError:
        return False
