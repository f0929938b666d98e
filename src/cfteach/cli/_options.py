"""Option definitions shared by the commands, so every command names a domain, a list, a
count, an output and a database the same way (docs/cli.md). Each function returns a fresh
`typer.Option` for an ``Annotated[...]`` parameter."""

from __future__ import annotations

from typing import Any

import typer

LIST_NOTE = "repeat the option or comma-separate"


def domain_list(default_text: str) -> Any:  # noqa: ANN401 - typer's OptionInfo
    """``--domain/-d``: an optional set of domains (the command has a default)."""
    return typer.Option("--domain", "-d", help=(
        f"Domains: built-in names, TOML files or random:WxH:fF:nN:sS specs ({LIST_NOTE}). "
        f"Default: {default_text}."))


def out(what: str) -> Any:  # noqa: ANN401
    """``--out/-o``: what the command writes (checked before any work)."""
    return typer.Option("--out", "-o", help=what)


def force(what: str = "Go on even when the size estimate exceeds the free memory.") -> Any:  # noqa: ANN401
    """``--force``: a flag (never ``--no-force``)."""
    return typer.Option("--force", help=what)


def quiet() -> Any:  # noqa: ANN401
    """``--quiet/-q``: no progress bars (they are also off when stderr is not a terminal)."""
    return typer.Option("--quiet", "-q", help="No progress bars (also off when stderr is "
                        "not a terminal).")


def workers() -> Any:  # noqa: ANN401
    """``--workers``: worker processes; the same default everywhere."""
    return typer.Option("--workers", help="Worker processes (default: one per independent "
                        "job, up to every local core: 1 for teach and tests, one per domain "
                        "for reproduce, learner chunks for simulate; dask/ray: the whole "
                        "cluster). The results are the same for any number.")


def study() -> Any:  # noqa: ANN401
    """``--study``: a study folder (from `cfteach study init`)."""
    return typer.Option("--study", help="Study folder (from `cfteach study init`).")


def db() -> Any:  # noqa: ANN401
    """``--db``: a database URL; default the SQLite file in the study folder."""
    return typer.Option("--db", help="Database URL (default: sqlite:///STUDY/study.db; "
                        "or postgresql+psycopg://user@host/db).")
