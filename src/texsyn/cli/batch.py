"""The ``batch`` command: every exemplar by every method with every seed, on Dask (``docs/batch.md``).

The work is :mod:`texsyn.batch` (:func:`~texsyn.batch.plan` the items,
:func:`~texsyn.batch.run` them); this command parses the options, shows the one progress
display and the Dask dashboard's address, and ends with one line: what was made, skipped
and failed. ``compare --batch`` (:mod:`~texsyn.cli.comparison`) runs through
:func:`run_batch` too.
"""

from __future__ import annotations

import functools

import click

from .common import done
from .options import SEED, SIZE, overwrite_option, param_option, per_method_params, quiet_option
from .progress import ProgressBar

__all__ = ["batch", "cluster_options", "run_batch"]


def cluster_options(command):
    """``--scheduler``, ``--workers``, ``--send-bytes``: where a batch runs."""

    @click.option(
        "--scheduler",
        metavar="ADDRESS",
        help="Run on the Dask cluster of this scheduler (tcp://host:8786) [default: a local cluster].",
    )
    @click.option(
        "--workers",
        type=click.IntRange(1, 4096),
        help="Processes of the local cluster, one thread each [default: the CPUs].",
    )
    @click.option(
        "--send-bytes",
        is_flag=True,
        help="The workers do not share this machine's files: send exemplars and outputs as bytes.",
    )
    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        if kwargs.get("scheduler") is not None and kwargs.get("workers") is not None:
            raise click.UsageError(
                "--workers sizes the local cluster; with --scheduler the cluster has its own"
            )
        return command(*args, **kwargs)

    return wrapper


def run_batch(items, *, label, quiet, scheduler, workers, send_bytes, overwrite=False, metrics=False):
    """Run ``items`` (:func:`texsyn.batch.run`) with a progress bar; print the dashboard's address."""
    from ..batch import run
    from ..batch.runner import dashboard_link

    def connected(client) -> None:
        if quiet:
            return
        link = dashboard_link(client)
        where = f"Dask scheduler {scheduler}" if scheduler else "a local Dask cluster"
        count = len(client.scheduler_info().get("workers", {}))
        click.echo(
            f"running on {where} ({count} worker{'s' * (count != 1)})"
            + (f"; dashboard: {link}" if link else ""),
            err=True,
        )

    bar = ProgressBar(label, enabled=not quiet, delay=0.0)
    try:
        return run(
            items,
            scheduler=scheduler,
            workers=workers,
            send_bytes=send_bytes,
            overwrite=overwrite,
            metrics=metrics,
            callback=bar,
            on_connect=connected,
        )
    finally:
        bar.close()


def parse_seed_list(texts: tuple[str, ...]) -> list[int] | None:
    """``--seed-list 1,2 --seed-list 7`` as ``[1, 2, 7]`` (``None`` when not given)."""
    if not texts:
        return None
    seeds = []
    for text in texts:
        for part in text.split(","):
            part = part.strip()
            if not part:
                continue
            try:
                seeds.append(SEED.convert(int(part), None, None))
            except (ValueError, click.BadParameter):
                raise click.UsageError(
                    f"--seed-list takes integers in [0, 2^64 - 1] separated by commas, got {text!r}"
                ) from None
    if not seeds:
        raise click.UsageError("--seed-list is empty")
    return seeds


@click.command()
@click.argument("inputs", nargs=-1, required=True)
@click.option(
    "-o",
    "--output",
    "outdir",
    required=True,
    type=click.Path(file_okay=False),
    help="Output folder: OUTDIR/<exemplar>/<method>-s<seed>.png and OUTDIR/manifest.jsonl.",
)
@click.option("-m", "--method", "methods", multiple=True, required=True, help="Method (repeatable).")
@click.option(
    "--seeds",
    type=click.IntRange(1, 1_000_000),
    help="Syntheses per exemplar and method, their seeds derived from --batch-seed [default: 1].",
)
@click.option(
    "--seed-list",
    "seed_list",
    multiple=True,
    metavar="N,N,...",
    help="The seeds themselves, used as they are (repeatable; excludes --seeds).",
)
@click.option(
    "--batch-seed", type=SEED, default=0, show_default=True, help="Seed the item seeds derive from."
)
@click.option("--size", type=SIZE, help="Output size WIDTHxHEIGHT [default: twice each exemplar].")
@param_option("Method parameter (repeatable).", metavar="METHOD.NAME=VALUE")
@cluster_options
@click.option("--metrics", is_flag=True, help="Measure every output and record the metrics in the manifest.")
@overwrite_option("Replace an existing output that is not what its item makes (finished items are kept).")
@quiet_option
def batch(
    inputs,
    outdir,
    methods,
    seeds,
    seed_list,
    batch_seed,
    size,
    params,
    scheduler,
    workers,
    send_bytes,
    metrics,
    overwrite,
    quiet,
):
    """Synthesise every exemplar of INPUTS (files, folders, glob patterns) with every method and seed.

    One output per (exemplar, method, seed): OUTDIR/<exemplar>/<method>-s<seed>.png, the same
    bytes as `texsyn synth EXEMPLAR -m METHOD --seed SEED`. OUTDIR/manifest.jsonl records
    each item; a rerun skips the finished ones. Runs on a local Dask cluster, or on an
    existing one with --scheduler.
    """
    from ..batch import plan

    if seeds is not None and seed_list:
        raise click.UsageError("give --seeds or --seed-list, not both")
    names = list(dict.fromkeys(methods))
    overrides = per_method_params(params, names)
    items = plan(
        inputs,
        outdir,
        names,
        seeds=seeds or 1,
        seed_list=parse_seed_list(seed_list),
        batch_seed=batch_seed,
        size=size,
        params=overrides,
    )
    records = run_batch(
        items,
        label="batch",
        quiet=quiet,
        scheduler=scheduler,
        workers=workers,
        send_bytes=send_bytes,
        overwrite=overwrite,
        metrics=metrics,
    )
    finish(records, outdir, quiet)


def finish(records, outdir: str, quiet: bool) -> None:
    """The closing line; exit status 1 when an item failed (its error is in the manifest)."""
    from ..batch import MANIFEST_NAME
    from .app import EXIT_FAILURE

    failed = [r for r in records if r.get("status") != "done"]
    made = records.computed - len(failed)
    manifest = f"{outdir.rstrip('/')}/{MANIFEST_NAME}"
    summary = (
        f"{len(records)} items in {outdir}: {made} made, {len(records) - records.computed} already done"
        + (f", {len(failed)} failed" if failed else "")
        + f"; manifest {manifest}"
    )
    if failed:  # said even with --quiet: the batch did not do all it was asked
        first = failed[0]
        click.echo(
            f"texsyn: error: {summary}; first failure: {first.get('output')}: {first.get('error')}", err=True
        )
        raise SystemExit(EXIT_FAILURE)
    done(quiet, None, False, summary)
