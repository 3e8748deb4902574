"""``subid methods``: the identification methods and the bundled datasets."""

from __future__ import annotations

import click

from subid.cli._shared import METHODS, _common, cli


@cli.command(name="methods", epilog="\b\nExample:\n  subid methods")
@_common
def methods_command():
    """List the identification methods and the bundled datasets."""
    from subid import datasets
    click.echo("methods (--method):")
    for name, spec in METHODS.items():
        status = "" if spec.available() else "  [not available in this version]"
        click.echo(f"  {name:<10} {spec.kind:<6} {spec.time:<10} {spec.description}{status}")
    click.echo("datasets (DATA = dataset:NAME):")
    for name in datasets.names():
        meta = datasets.info(name)
        click.echo(f"  {name:<14} {meta['n_samples']:>5} samples, {meta['n_inputs']} in, "
                   f"{meta['n_outputs']} out, dt = {meta['dt']:g}"
                   + ("" if meta["dt_known"] else " (assumed)"))
    return 0
