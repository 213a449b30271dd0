"""The ``methods`` command: every registered method with its paper and parameters.

The list is read from the registry (:data:`texsyn.methods.METHODS`) and each method's
``__init__`` signature (:meth:`~texsyn.methods.TextureSynthesizer.param_specs`), so that a
new method or parameter appears here without a change to the command line.
"""

from __future__ import annotations

import click

from ..methods import METHODS

__all__ = ["list_methods"]


@click.command("methods")
def list_methods() -> None:
    """List the methods with their papers and parameters (defaults and allowed values)."""
    for name in sorted(METHODS):
        cls = METHODS[name]
        click.echo(f"{name}: {cls.summary}")
        click.echo(f"  paper: {cls.reference}")
        click.echo(f"  source map: {'yes' if cls.has_source_map else 'no'}")
        specs = cls.param_specs()
        if not specs:
            click.echo("  parameters: none")
        else:
            click.echo("  parameters:")
            for spec in specs.values():
                click.echo(
                    f"    {spec.name} = {spec.text(spec.default)}  ({spec.type.__name__}, allowed {spec.describe_allowed()})"
                    + (f"  {spec.description}" if spec.description else "")
                )
        click.echo("")
