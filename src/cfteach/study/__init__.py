"""The user-study platform: a FastAPI server, its database, participant UI and data export.

Public entry points: `create_app` (server), `init_study` (study folder from curricula and
tests), `export_csv` (tidy CSVs for the analysis).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__all__ = ["create_app", "init_study", "export_csv", "load_study"]

if TYPE_CHECKING:  # pragma: no cover
    from .build import init_study
    from .config import load_study
    from .export import export_csv
    from .server import create_app


def __getattr__(name: str) -> Any:
    # Lazy so `import cfteach.study` stays cheap for the CLI.
    if name == "create_app":
        from .server import create_app

        return create_app
    if name == "init_study":
        from .build import init_study

        return init_study
    if name == "export_csv":
        from .export import export_csv

        return export_csv
    if name == "load_study":
        from .config import load_study

        return load_study
    raise AttributeError(name)
