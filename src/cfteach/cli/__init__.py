"""The `cfteach` command line: one module per command family, each with `register(app)`."""

from __future__ import annotations

import importlib

import typer

app = typer.Typer(
    name="cfteach",
    help="Counterfactual-aware teaching of a robot's reward through demonstrations.",
    no_args_is_help=True,
    add_completion=False,
)

# Each module owns one family of commands; registering them here keeps this file stable.
_COMMAND_MODULES = (
    "domains_cmd",
    "teach_cmd",
    "render_cmd",
    "reproduce_cmd",
    "simulate_cmd",
    "study_cmd",
    "analyze_cmd",
    "export_cmd",
)



@app.command()
def version() -> None:
    """Print cfteach's version."""
    from cfteach import __version__

    typer.echo(__version__)


for _name in _COMMAND_MODULES:
    importlib.import_module(f"{__name__}.{_name}").register(app)


def main() -> None:
    """Entry point of the `cfteach` console script."""
    app()
