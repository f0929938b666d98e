"""What every command shares: one error style, output checks before the work, and loading a
domain with every check (file, features, size, planning) before anything is computed.

Errors are one line, ``Error: ...`` on stderr; exit status 2 for a usage error (a bad
argument or option, a domain that cannot be taught), 1 for a failure during the work.
"""

from __future__ import annotations

import difflib
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import typer

#: Exit status of a usage error (as click uses for bad options).
USAGE = 2


def fail(message: str, code: int = USAGE) -> NoReturn:
    """Print ``Error: message`` on stderr and exit."""
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(code)


def did_you_mean(value: str, choices: Sequence[str]) -> str:
    """``"; did you mean 'x'?"`` for a close match, else ``""``."""
    close = difflib.get_close_matches(value, list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def check_choice(value: str, choices: Sequence[str], option: str) -> None:
    """One line naming a value outside `choices`, with the allowed ones and a close match."""
    if value not in choices:
        fail(f"{option}: unknown value {value!r} (allowed: {', '.join(choices)})"
             + did_you_mean(value, choices))


def _writable_dir(folder: Path) -> Path | None:
    """The nearest existing ancestor of `folder` if it is not a writable directory."""
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            return None
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        return probe
    try:  # access() says yes to root everywhere: try it (/proc, read-only mounts)
        os.rmdir(tempfile.mkdtemp(prefix=".cfteach-probe-", dir=probe))
    except OSError:
        return probe
    return None


def check_out_file(path: Path | None, option: str = "--out") -> None:
    """Before any work: `path` can be written as a file (not a directory, its folder
    writable or creatable)."""
    if path is None:
        return
    if path.is_dir():
        fail(f"{option} {path}: is a directory; give a file name, e.g. {path / 'out.json'}")
    if path.exists() and not os.access(path, os.W_OK):
        fail(f"{option} {path}: the file exists and is not writable")
    bad = _writable_dir(path.parent)
    if bad is not None:
        fail(f"{option} {path}: cannot write into {bad} "
             f"({'not a directory' if not bad.is_dir() else 'not writable'})")


def check_out_dir(path: Path, option: str = "--out") -> None:
    """Before any work: `path` is (or can be created as) a writable directory."""
    if path.exists() and not path.is_dir():
        fail(f"{option} {path}: is a file, not a directory")
    bad = _writable_dir(path)
    if bad is not None:
        fail(f"{option} {path}: cannot write into {bad} "
             f"({'not a directory' if not bad.is_dir() else 'not writable'})")


def check_positive(value: int | None, option: str) -> None:
    """Reject 0 and negative counts at parse time."""
    if value is not None and value < 1:
        fail(f"{option} must be at least 1, got {value}")


#: The help of every command's ``--envs`` option.
ENVS_HELP = ("Work on these environments only: comma-separated indices (5), env codes of "
             "the domain's bit count (000101) and slices start:stop:step (0::16 = every "
             "16th). The JSON keeps each one's original index and code.")


def load_domain(name: str, *, force: bool = False, sphere: bool = False,
                planning: bool = True, envs: str | None = None) -> Any:
    """Load a domain (name, file or random spec) and run every check before any work.

    `sphere`: the command draws 3-D belief pictures, which need exactly 3 features.
    `force`: go on when the size estimate exceeds the free memory.
    `planning`: also run the planning checks (unreachable goals, reward loops), which
    compile the domain (as teaching would anyway).
    `envs`: restrict the domain to these environments (``--envs``, checked before any
    work; the size estimate and the planning checks then cover only those).
    """
    from cfteach import domains
    from cfteach.domains.check import errors_of, static_findings
    from cfteach.domains.size import available_memory, estimate_size, human_bytes, shrink_advice
    from cfteach.mdp.soundness import require_sound

    try:
        dom = domains.load(name)
    except ValueError as exc:  # DomainFileError, unknown names, bad random specs
        fail(str(exc))
    errors = errors_of(static_findings(dom))
    if errors:
        fail(errors[0].message)
    if envs is not None:
        from cfteach.domains.selection import subset

        try:
            dom = subset(dom, envs)
        except ValueError as exc:
            fail(f"--envs: {exc}")
    if sphere and dom.n_features != 3:
        fail(f"{dom.name}: {dom.n_features} features; the report's belief pictures are "
             "spheres and need exactly 3 (use --no-report for the JSON only, or "
             "`cfteach teach` / `cfteach tests`)")
    est = estimate_size(dom)
    free = available_memory()
    if free is not None and free / 2 < est.teach_peak_bytes <= free:
        typer.echo(f"warning: {dom.name}: teaching needs about "
                   f"{human_bytes(est.teach_peak_bytes)}, more than half of the "
                   f"{human_bytes(free)} free: {shrink_advice(dom, est)}", err=True)
    if free is not None and est.teach_peak_bytes > free and not force:
        fail(f"{dom.name}: teaching needs about {human_bytes(est.teach_peak_bytes)} of memory "
             f"({est.instances} instances, about {est.demonstrations} demonstrations), "
             f"{human_bytes(free)} is free: {shrink_advice(dom, est)}; or pass --force")
    if planning:
        try:
            require_sound(dom)
        except ValueError as exc:
            fail(str(exc))
    return dom


def sqlite_path(url: str) -> Path | None:
    """The file of a ``sqlite:///...`` URL (None for other databases or in-memory)."""
    from sqlalchemy.engine import make_url

    try:
        u = make_url(url)
    except Exception:  # noqa: BLE001 - any unparsable URL is a usage error
        fail(f"--db {url!r} is not a database URL (e.g. sqlite:///study/study.db or "
             "postgresql+psycopg://user@host/db)")
    if not u.drivername.startswith("sqlite") or not u.database or u.database == ":memory:":
        return None
    return Path(u.database)


def study_sessions(url: str) -> int | None:
    """Sessions stored in a study database, None if the URL holds no study database.
    Never creates a database (an SQLite file that does not exist is not opened)."""
    from sqlalchemy import create_engine, inspect, text
    from sqlalchemy.exc import SQLAlchemyError

    path = sqlite_path(url)
    if path is not None and not path.is_file():
        return None
    engine = create_engine(url)
    try:
        with engine.connect() as conn:
            if not inspect(conn).has_table("sessions"):
                return None
            return int(conn.execute(text("SELECT COUNT(*) FROM sessions")).scalar_one())
    except SQLAlchemyError as exc:
        fail(f"--db {url}: cannot read the database ({type(exc).__name__}: "
             f"{str(exc).splitlines()[0]})")
    finally:
        engine.dispose()


def check_known(dom: Any, known: str | None) -> tuple[str, ...] | None:
    """--known checked against the domain (one line naming the problem), or None: every
    command that teaches checks it before any work."""
    if known is None:
        return None
    from cfteach.teaching.known import known_names

    try:
        return known_names(dom, known)
    except ValueError as exc:
        fail(f"--known: {exc}")
    return None  # pragma: no cover - fail exits
