"""Commands of this family are added as their issues land."""

import typer


def register(app: typer.Typer) -> None:
    """Add this module's commands to the `cfteach` app."""
