"""The `cfteach` command line (docs/cli.md). `app` is the Typer app; it is built on first
use, so `cfteach --version` answers before Typer, click or any command module is imported."""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["app", "main"]


def __getattr__(name: str) -> Any:  # noqa: ANN401 - the Typer app
    if name == "app":
        from cfteach.cli._app import app

        return app
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def main() -> None:
    """Entry point of the `cfteach` console script: no traceback reaches the user (set
    CFTEACH_DEBUG=1 to see one)."""
    if sys.argv[1:] == ["--version"]:
        from cfteach import __version__

        print(f"cfteach {__version__}")
        return
    from cfteach.cli._app import main as run

    run()
