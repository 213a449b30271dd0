"""Batch runs: many exemplars, methods and seeds on a laptop or a Dask cluster (``docs/batch.md``).

>>> import texsyn.batch  # doctest: +SKIP
>>> items = texsyn.batch.plan(["textures/"], "out", ["quilting"], seeds=4)  # doctest: +SKIP
>>> records = texsyn.batch.run(items)  # doctest: +SKIP

The parts: :mod:`~texsyn.batch.items` (the items, their seeds and file names),
:mod:`~texsyn.batch.synthesis` (one output made exactly as ``texsyn synth`` makes it),
:mod:`~texsyn.batch.tasks` (what a worker runs), :mod:`~texsyn.batch.manifest` (the record
of finished items that makes a rerun skip them), :mod:`~texsyn.batch.runner` (the Dask
client and the loop) and :mod:`~texsyn.batch.report` (``texsyn compare --batch``). Dask
loads only when :func:`run` starts a batch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:  # the names for type checkers; at run time ``__getattr__`` loads them
    from .items import BatchItem, expand_inputs, item_seed, plan
    from .manifest import MANIFEST_NAME, Manifest
    from .runner import BatchRecords, connect, run

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "BatchItem": "items",
        "BatchRecords": "runner",
        "MANIFEST_NAME": "manifest",
        "Manifest": "manifest",
        "connect": "runner",
        "expand_inputs": "items",
        "item_seed": "items",
        "plan": "items",
        "run": "runner",
    },
)

__all__ = [
    "MANIFEST_NAME",
    "BatchItem",
    "BatchRecords",
    "Manifest",
    "connect",
    "expand_inputs",
    "item_seed",
    "plan",
    "run",
]
