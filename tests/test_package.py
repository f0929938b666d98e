"""The package imports and the console script answers."""

from typer.testing import CliRunner

import cfteach
from cfteach.cli import app


def test_version_is_set() -> None:
    assert cfteach.__version__.count(".") == 2


def test_cli_help_lists_usage() -> None:
    result = CliRunner().invoke(app, ["--help"])
    assert result.exit_code == 0
    assert "Usage" in result.output
