"""The ``compare`` command: several methods on one exemplar, as an HTML report (``docs/cli.md``).

The comparison itself is :func:`texsyn.report.run_comparison`; this command parses the
``METHOD.NAME=VALUE`` parameters, claims the report's two files before any work, and shows
the one progress display while the methods run. With ``--batch`` it compares the methods on
every exemplar of folders, files or patterns through the batch machinery (:mod:`texsyn.batch`,
``docs/batch.md``): the outputs and their manifest go to ``--outdir``, and the report
(:mod:`texsyn.batch.report`) is built from the manifest.
"""

from __future__ import annotations

import click

from .._version import __version__
from ..methods import METHODS, get_method
from .batch import cluster_options, finish, run_batch
from .common import command_line, done, input_path, load_exemplar, output_set
from .options import (
    BUILTIN_PREFIX,
    SIZE,
    output_option,
    overwrite_option,
    param_option,
    per_method_params,
    quiet_option,
)
from .progress import ProgressBar

__all__ = ["compare"]


@click.command()
@click.argument("exemplars", nargs=-1)
@output_option("Report file (.html); a .json sidecar with the same name is written beside it.")
@click.option(
    "-m", "--method", "methods", multiple=True, help="Method to compare (repeatable; all methods by default)."
)
@click.option(
    "--seeds",
    type=click.IntRange(min=1, max=100),
    default=1,
    show_default=True,
    help="Syntheses per method (seeds 0..N-1).",
)
@click.option("--size", type=SIZE, help="Output size WIDTHxHEIGHT [default: twice the exemplar].")
@param_option("Method parameter (repeatable).", metavar="METHOD.NAME=VALUE")
@click.option(
    "--batch",
    "batch_mode",
    is_flag=True,
    help="Compare on every exemplar of EXEMPLARS (files, folders, glob patterns) through the batch machinery.",
)
@click.option(
    "--outdir",
    type=click.Path(file_okay=False),
    help="With --batch: the folder of the outputs and their manifest [default: REPORT_files beside the report].",
)
@cluster_options
@overwrite_option("Replace an existing report and its sidecar.")
@quiet_option
def compare(
    exemplars,
    output,
    methods,
    seeds,
    size,
    params,
    batch_mode,
    outdir,
    scheduler,
    workers,
    send_bytes,
    overwrite,
    quiet,
):
    """Run several methods on EXEMPLAR and write an HTML report with metrics and timings.

    With --batch, EXEMPLARS are files, folders or glob patterns, and the report has a table
    per exemplar and a summary table (mean metrics per method).
    """
    from ..report import claim_report, run_comparison, write_report  # the metrics load only when needed

    names = list(dict.fromkeys(methods)) or sorted(METHODS)
    for name in names:
        get_method(name)
    overrides = per_method_params(params, names)
    if batch_mode:
        compare_batch(
            exemplars,
            output,
            names,
            seeds,
            size,
            overrides,
            outdir,
            scheduler,
            workers,
            send_bytes,
            overwrite,
            quiet,
        )
        return
    if outdir is not None or scheduler is not None or workers is not None or send_bytes:
        raise click.UsageError("--outdir, --scheduler, --workers and --send-bytes go with --batch")
    if len(exemplars) > 1:
        raise click.UsageError(
            "compare takes one EXEMPLAR; give --batch to compare on several (files, folders, patterns)"
        )
    exemplar = exemplars[0] if exemplars else None
    outputs = output_set(overwrite)
    outputs.add_input(input_path(exemplar), "exemplar")
    html_path, _ = claim_report(outputs, output)

    image, label = load_exemplar(exemplar)
    bar = ProgressBar("compare", enabled=not quiet, delay=0.0)
    try:
        report = run_comparison(
            image, names, seeds=seeds, shape=size, exemplar_name=label, params=overrides, callback=bar
        )
    finally:
        bar.close()
    metadata = {
        "texsyn_version": __version__,
        "command_line": command_line(),
        "exemplar_path": exemplar or f"{BUILTIN_PREFIX}brick",
    }
    html_out, json_out = write_report(report, html_path, outputs=outputs, metadata=metadata)
    failed = [r.method for r in report.records if r.error]
    done(
        quiet,
        None,
        False,
        f"wrote {html_out} and {json_out}" + (f"; failed: {', '.join(failed)}" if failed else ""),
    )


def compare_batch(
    inputs, output, names, seeds, size, overrides, outdir, scheduler, workers, send_bytes, overwrite, quiet
):
    """``compare --batch``: every method on every exemplar (seeds ``0..N-1``), one report from the manifest."""
    import json
    from pathlib import Path

    from ..batch import plan
    from ..batch.report import batch_report, render_batch_html
    from ..report import claim_report

    if not inputs:
        raise click.UsageError("--batch needs EXEMPLARS: image files, folders or glob patterns")
    outputs = output_set(overwrite)
    html_path, json_path = claim_report(outputs, output)
    folder = Path(outdir) if outdir is not None else html_path.with_name(html_path.stem + "_files")
    items = plan(inputs, folder, names, seed_list=list(range(seeds)), size=size, params=overrides)
    for item in items:
        outputs.add_input(item.exemplar if not item.exemplar.startswith(BUILTIN_PREFIX) else None, "exemplar")
    records = run_batch(
        items,
        label="compare",
        quiet=quiet,
        scheduler=scheduler,
        workers=workers,
        send_bytes=send_bytes,
        metrics=True,
    )
    metadata = {"command_line": command_line(), "report": str(html_path)}
    data = batch_report(records, folder, metadata=metadata)
    with outputs:
        outputs.write_text(html_path, render_batch_html(data, html_path))
        outputs.write_text(json_path, json.dumps(data, indent=2))
    if not quiet:
        click.echo(f"wrote {html_path} and {json_path}", err=True)
    finish(records, str(folder), quiet)
