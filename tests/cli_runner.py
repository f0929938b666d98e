"""typer's CliRunner with a fixed, wide terminal, so no CLI-output assertion depends on the
width of the terminal the tests run in (rich wraps error boxes to `COLUMNS`, 80 when unset)."""

from __future__ import annotations

from typing import Any

from typer.testing import CliRunner

WIDTH = "1000"  # wider than any message or temporary path the tests print


class WideRunner(CliRunner):
    """`invoke` with `COLUMNS` set for the duration of the call (caller's `env` wins)."""

    def invoke(self, *args: Any, env: dict[str, str] | None = None, **kw: Any):  # noqa: ANN401, ANN201
        return super().invoke(*args, env={"COLUMNS": WIDTH, **(env or {})}, **kw)
