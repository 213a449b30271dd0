"""The ``compare`` command: several methods on one exemplar, as an HTML report (``docs/cli.md``).

The comparison itself is :func:`texsyn.report.run_comparison`; this command parses the
``METHOD.NAME=VALUE`` parameters, claims the report's two files before any work, and shows
the one progress display while the methods run.
"""

from __future__ import annotations

import click

from .._version import __version__
from ..errors import InputError
from ..methods import METHODS, get_method
from .common import command_line, done, input_path, load_exemplar, output_set
from .options import (
    BUILTIN_PREFIX,
    SIZE,
    output_option,
    overwrite_option,
    param_option,
    parse_params,
    quiet_option,
)
from .progress import ProgressBar

__all__ = ["compare"]


@click.command()
@click.argument("exemplar", required=False)
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
@overwrite_option("Replace an existing report and its sidecar.")
@quiet_option
def compare(exemplar, output, methods, seeds, size, params, overwrite, quiet):
    """Run several methods on EXEMPLAR and write an HTML report with metrics and timings."""
    from ..report import claim_report, run_comparison, write_report  # the metrics load only when needed

    names = list(dict.fromkeys(methods)) or sorted(METHODS)
    for name in names:
        get_method(name)
    overrides: dict[str, dict] = {}
    for item in params:
        key = item.split("=", 1)[0]
        if "." not in key or "=" not in item:
            raise click.UsageError(f"parameters are given as METHOD.NAME=VALUE, got {item!r}")
        method, rest = item.split(".", 1)
        if method not in names:
            raise InputError(f"parameter {item!r} names method {method!r}, which is not compared")
        overrides.setdefault(method, {}).update(parse_params(method, (rest,)))
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
