"""Running a batch on Dask distributed: a local cluster by default, or an existing one.

:func:`run` reads the manifest, skips the items whose output still has its recorded checksum,
and sends the others to the cluster: one :func:`~texsyn.batch.tasks.fit_task` per (exemplar,
method, parameters), whose fitted model stays on a worker as a Dask future, and one
:func:`~texsyn.batch.tasks.item_task` per item that takes it. Each finished item is recorded
in the manifest at once (``docs/batch.md``). Tasks carry paths where the workers see the
client's files, or, with ``send_bytes``, the exemplar's bytes (scattered once) and the
output's bytes back. A worker that dies takes its tasks with it; Dask runs them again on
another worker (and fits again where the fitted model was lost). Ctrl-C cancels what is left:
the manifest holds every item finished so far, and the rerun continues.

Dask is imported here only, when a batch runs: ``import texsyn`` and ``import texsyn.batch``
do not load it.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from ..errors import InputError
from ..io import OutputSet
from ..ops.linalg import worker_count
from ..ops.progress import Progress
from .items import BatchItem
from .manifest import Manifest, verified
from .tasks import ONE_THREAD_ENVIRONMENT, ExemplarBytes, describe_error, fit_task, item_task

__all__ = ["BatchRecords", "connect", "run"]

#: the Dask setting that puts ``MALLOC_TRIM_THRESHOLD_`` in a nanny's workers (``None`` leaves it out)
TRIM_SETTING = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"

#: how many times Dask runs a task again after it raised (a worker that dies is handled apart)
DEFAULT_RETRIES = 2


class BatchRecords(list):
    """The manifest records of a batch's items, in the items' order (a ``list`` of ``dict``).

    Attributes
    ----------
    computed : int
        Items made in this run (the others were finished already and skipped).
    """

    computed: int = 0

    def to_dataframe(self):
        """The records as a pandas ``DataFrame`` (one row per item; ``metrics.NAME`` columns)."""
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - pandas is in the test extra
            raise ImportError("to_dataframe needs pandas: pip install pandas") from exc
        return pd.json_normalize(list(self))


@contextmanager
def connect(
    client=None,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
) -> Iterator[Any]:
    """A Dask client: ``client`` itself, one connected to ``scheduler``, or a new local cluster's.

    The local cluster has ``workers`` processes (the CPUs by default) of one thread each, every
    thread library capped at one thread (:data:`~texsyn.batch.tasks.ONE_THREAD_ENVIRONMENT`),
    and its web server (the dashboard, when bokeh is installed) on a free port. What this
    function starts it also stops.
    """
    if client is not None:
        yield client
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise InputError('texsyn batch needs Dask: pip install "texsyn[batch]"') from exc
    if scheduler is not None:
        try:
            with Client(scheduler, timeout="10s") as remote:
                yield remote
        except OSError as exc:
            raise InputError(f"cannot reach the Dask scheduler at '{scheduler}': {exc}") from exc
        return
    import dask

    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which hands every freed
    # array back to the system and makes texsyn's syntheses about 25 % slower
    # (benchmarks/results.md, "Batch runs on Dask"): glibc's own policy is kept instead
    with dask.config.set({TRIM_SETTING: None}):
        cluster = LocalCluster(
            n_workers=workers or worker_count(),
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",  # a free port: 8787 may be another cluster's
            silence_logs=logging.ERROR,
            env=dict(ONE_THREAD_ENVIRONMENT),
        )
    with cluster, Client(cluster) as local:
        yield local


def dashboard_link(client) -> str | None:
    """The address of the cluster's dashboard, or ``None`` when it has none (no bokeh on the scheduler)."""
    try:
        if "dashboard" not in client.scheduler_info().get("services", {}):
            return None
        if not client.run_on_scheduler(_has_bokeh):
            return None
        return str(client.dashboard_link)
    except Exception:  # an address we cannot tell is not worth stopping the batch for
        return None


def _has_bokeh() -> bool:
    """Whether bokeh, which draws the dashboard's pages, is installed (run on the scheduler)."""
    return importlib.util.find_spec("bokeh") is not None


def run(
    items: Sequence[BatchItem],
    client=None,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    retries: int = DEFAULT_RETRIES,
    send_bytes: bool = False,
    overwrite: bool = False,
    metrics: bool = False,
    callback: Callable[[Progress], None] | None = None,
    on_connect: Callable[[Any], None] | None = None,
) -> BatchRecords:
    """Make every item that is not finished yet, on Dask; return every item's manifest record.

    Parameters
    ----------
    items : sequence of BatchItem
        From :func:`texsyn.batch.plan`; all write into one output folder, whose
        ``manifest.jsonl`` records each item as it finishes.
    client : distributed.Client, optional
        The cluster to use. Without it (and without ``scheduler``) a local cluster of
        ``workers`` processes with one thread each runs the batch.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    workers : int, optional
        Processes of the local cluster (the CPUs by default).
    retries : int
        How many times a task that raised runs again (a failure of the item itself is
        recorded, not raised, so this concerns the cluster's failures).
    send_bytes : bool
        The workers do not see the client's files: send each exemplar's bytes and receive
        each output's bytes (the client writes the files).
    overwrite : bool
        Replace an output that exists and is not this item's (without it that item fails).
    metrics : bool
        Measure every output (:func:`texsyn.metrics.evaluate`) and record the metrics.
    callback : callable, optional
        Receives :class:`~texsyn.ops.progress.Progress` records (stage ``"items"``) as items finish.
    on_connect : callable, optional
        Called with the Dask client once connected (the command line prints the dashboard).

    Returns
    -------
    BatchRecords
        A list of dicts, one per item in ``items``'s order (``to_dataframe()`` with pandas).
    """
    items = list(items)
    if not items:
        return BatchRecords()
    outdirs = {os.path.abspath(item.outdir) for item in items}
    if len(outdirs) != 1:
        raise InputError("the items of one batch must share one output folder")
    ids = [item.id for item in items]
    if len(set(ids)) != len(ids):
        raise InputError("the batch names an item twice")
    outputs = [item.output for item in items]
    if len(set(outputs)) != len(outputs):
        raise InputError("two items of the batch name the same output file")
    total = len(items)
    records: dict[str, dict] = {}
    with Manifest(outdirs.pop()) as manifest:
        previous = manifest.read()
        pending = []
        for item in items:
            record = previous.get(item.id)
            if verified(item, record) and (not metrics or record.get("metrics")):  # type: ignore[union-attr]
                records[item.id] = previous[item.id]
            else:
                pending.append(item)
        result = BatchRecords()
        result.computed = len(pending)
        report = _reporter(callback, total)
        report(len(records))
        if pending:
            with connect(client, scheduler=scheduler, workers=workers) as dask_client:
                if on_connect is not None:
                    on_connect(dask_client)
                for record in _compute(dask_client, pending, retries, send_bytes, overwrite, metrics):
                    records[record["id"]] = record
                    manifest.append(record)
                    report(len(records))
        result.extend(records[i] for i in ids)
    return result


def _reporter(callback, total: int) -> Callable[[int], None]:
    def report(done: int) -> None:
        if callback is not None:
            callback(Progress("items", done, total))

    return report


def _compute(
    client, pending: list[BatchItem], retries: int, send_bytes: bool, overwrite: bool, metrics: bool
):
    """Submit the fits and the items; yield each item's record as it finishes."""
    from distributed import as_completed

    token = uuid.uuid4().hex[:8]  # keys unique to this run, whatever the client ran before
    groups: dict[str, list[BatchItem]] = {}
    for item in pending:
        groups.setdefault(item.fit_key, []).append(item)
    sources: dict[str, Any] = {}
    futures: dict[Any, BatchItem] = {}
    try:
        for key, group in groups.items():
            first = group[0]
            source = _source(client, first, send_bytes, sources)
            fit = client.submit(
                fit_task, source, first.method, first.params, key=f"texsyn-fit-{key}-{token}", retries=retries
            )
            for item in group:
                future = client.submit(
                    item_task,
                    item,
                    fit,
                    send_bytes=send_bytes,
                    overwrite=overwrite,
                    metrics=metrics,
                    key=f"texsyn-item-{item.id}-{token}",
                    retries=retries,
                )
                futures[future] = item
            del fit  # Dask keeps the fitted model while its items need it, and no longer
        for future in as_completed(list(futures)):
            item = futures.pop(future)
            try:
                record = future.result()
            except Exception as exc:  # the cluster gave up on it (a worker died too often...)
                record = {**item.to_dict(), "status": "failed", "sha256": None, "error": describe_error(exc)}
            if send_bytes and record.get("status") == "done":
                record = _write_received(item, record, overwrite)
            record.pop("data", None)
            yield record
    finally:
        if futures:  # stopped early (Ctrl-C, an error): nothing more runs for this batch
            client.cancel(list(futures), force=True)


def _source(client, item: BatchItem, send_bytes: bool, sources: dict) -> Any:
    """The exemplar as the fit task receives it: an absolute path, or its bytes scattered once."""
    if item.exemplar.startswith("builtin:"):
        return item.exemplar
    if not send_bytes:
        return os.path.abspath(item.exemplar)
    if item.exemplar_sha256 not in sources:
        with open(item.exemplar, "rb") as f:
            data = ExemplarBytes(os.path.basename(item.exemplar), f.read())
        sources[item.exemplar_sha256] = client.scatter(data, hash=False)
    return sources[item.exemplar_sha256]


def _write_received(item: BatchItem, record: dict, overwrite: bool) -> dict:
    """Write an output a worker sent as bytes (all or nothing); keep an existing one only if identical."""
    data = record["data"]
    path = item.output_path
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.exists() and not overwrite:
            with open(path, "rb") as f:
                same = f.read() == data
            if not same:
                raise InputError(
                    f"output '{path}' exists and is not what this item makes; --overwrite replaces it"
                )
            record["adopted"] = True
            return record
        outputs = OutputSet(overwrite=True)
        outputs.claim(path)
        with outputs:
            outputs.write(path, lambda tmp: _write_bytes(tmp, data))
    except Exception as exc:
        record.update(status="failed", sha256=None, error=describe_error(exc))
    return record


def _write_bytes(path, data: bytes) -> None:
    with open(path, "wb") as f:
        f.write(data)
