"""The package imports and the console script answers."""

import cfteach
from cfteach.cli import app
from cli_runner import WideRunner


def test_version_is_set() -> None:
    assert cfteach.__version__.count(".") == 2


def test_cli_help_lists_usage() -> None:
    result = WideRunner().invoke(app, ["--help"])
    assert result.exit_code == 0
    assert "Usage" in result.output


def test_cli_help_imports_no_heavy_library() -> None:
    """`cfteach --help` stays fast: the command modules import numpy, pandas, matplotlib,
    the web stack and the like inside their commands, not at registration."""
    import subprocess
    import sys

    heavy = ("numpy", "pandas", "scipy", "matplotlib", "sqlalchemy", "fastapi", "jinja2",
             "gymnasium", "PIL", "joblib", "tqdm")
    code = ("import sys; from cfteach.cli import app; "
            f"print(' '.join(m for m in {heavy!r} if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.split() == []
