"""Checks of a server's address and a database URL, made before anything is printed or
started, so a bad value is one line naming it (not a working-looking URL, then a failure)."""

from __future__ import annotations

import socket

from cfteach.cli._common import fail, sqlite_path

#: Databases the study runs on (docs/study.md): SQLite by default, PostgreSQL by URL.
DIALECTS = ("sqlite", "postgresql")


def check_db_url(url: str, option: str = "--db", *, must_exist: bool = False) -> None:
    """A URL of a supported database whose folder (SQLite) exists."""
    from sqlalchemy.engine import make_url

    try:
        u = make_url(url)
    except Exception:  # noqa: BLE001 - any unparsable URL is a usage error
        fail(f"{option} {url!r} is not a database URL (e.g. sqlite:///study/study.db or "
             "postgresql+psycopg://user@host/db)")
    dialect = u.get_backend_name()
    if dialect not in DIALECTS:
        fail(f"{option} {url}: {dialect!r} databases are not supported; use "
             "sqlite:///FILE or postgresql+psycopg://user@host/db")
    if dialect == "postgresql":
        driver = u.get_driver_name()
        try:
            __import__({"psycopg": "psycopg", "psycopg2": "psycopg2"}.get(driver, driver))
        except ImportError:
            fail(f"{option} {url}: the PostgreSQL driver {driver!r} is not installed "
                 "(pip install 'cfteach[postgres]' and write postgresql+psycopg://...)")
        return
    path = sqlite_path(url)
    if path is None:
        return
    if must_exist and not path.is_file():
        fail(f"{option} {url}: no database file at {path} (export never creates one; "
             "give --study FOLDER or --db URL)")
    if not path.parent.is_dir():
        fail(f"{option} {url}: the folder {path.parent} does not exist")


def check_port(host: str, port: int) -> None:
    """`port` is a valid port number that `host` can listen on right now."""
    if not 1 <= port <= 65535:
        fail(f"--port {port}: a port is a number from 1 to 65535")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        fail(f"--host {host}: not an address of this machine ({exc.strerror})")
    family, kind, proto, _, addr = infos[0]
    with socket.socket(family, kind, proto) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn does
        try:
            sock.bind(addr)
        except OSError as exc:
            reason = "is in use" if exc.errno in (98, 48, 10048) else f"({exc.strerror})"
            fail(f"--port {port}: {host}:{port} {reason}; choose another port")
