"""Engines and migrations: SQLite (WAL, synchronous FULL) by default, PostgreSQL by URL."""

from __future__ import annotations

import sqlite3
import threading
from pathlib import Path

from sqlalchemy import Engine, create_engine, event, text

HERE = Path(__file__).parent
WRITE_WAIT_S = 30.0  # as SQLite's busy_timeout: then "database is locked"


def _queued_writers() -> type[sqlite3.Connection]:
    """A sqlite3 connection class whose write transactions queue on one in-process lock.

    SQLite lets one writer in at a time; the others poll with growing sleeps (its busy
    handler: 1, 2, 5 ... 100 ms), unfairly, so under load some waited seconds while the lock
    was free most of the time (bench/bench_study_load.py showed it). Threads of one
    server now wait on a lock that hands over at once; other processes still meet the busy
    handler.
    """
    lock = threading.Lock()

    class QueuedWriters(sqlite3.Connection):
        holds_write_lock = False

        def wait_for_write_lock(self) -> None:
            if not lock.acquire(timeout=WRITE_WAIT_S):
                raise sqlite3.OperationalError("database is locked (in-process writers)")
            self.holds_write_lock = True

        def release_write_lock(self) -> None:
            if self.holds_write_lock:
                self.holds_write_lock = False
                lock.release()

        def commit(self) -> None:
            try:
                super().commit()
            finally:
                self.release_write_lock()

        def rollback(self) -> None:
            try:
                super().rollback()
            finally:
                self.release_write_lock()

        def close(self) -> None:
            try:
                super().close()
            finally:
                self.release_write_lock()

    return QueuedWriters


def make_engine(url: str) -> Engine:
    """An engine with the durability settings the study needs."""
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30,
                                                  "factory": _queued_writers()})

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn, _rec):  # noqa: ANN001
            dbapi_conn.isolation_level = None  # we emit BEGIN ourselves (below)
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=FULL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.close()

        @event.listens_for(engine, "begin")
        def _begin(conn):  # noqa: ANN001
            # Take the write lock up front: read-then-write transactions (assignment,
            # step advance) cannot interleave, even across processes. Read-only work
            # (engine.execution_options(readonly=True)) takes no lock.
            if conn.get_execution_options().get("readonly"):
                conn.exec_driver_sql("BEGIN")
                return
            dbapi_conn = conn.connection.dbapi_connection
            dbapi_conn.wait_for_write_lock()  # released by its commit or rollback
            try:
                conn.exec_driver_sql("BEGIN IMMEDIATE")
            except BaseException:
                dbapi_conn.release_write_lock()
                raise

        return engine
    if url.startswith("postgresql"):
        return create_engine(url, pool_size=10, max_overflow=20, pool_pre_ping=True)
    raise ValueError(f"unsupported database URL {url!r}: use sqlite:///PATH or "
                     "postgresql+psycopg://USER@HOST/DB")


def alembic_config(url: str):  # noqa: ANN201
    from alembic.config import Config

    cfg = Config(str(HERE / "alembic.ini"))
    cfg.set_main_option("script_location", str(HERE / "migrations"))
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def drop_schema(engine: Engine) -> None:
    """Drop every study table and Alembic's version table (a clean database for tests)."""
    from .models import Base

    with engine.begin() as conn:
        Base.metadata.drop_all(conn)
        conn.execute(text("DROP TABLE IF EXISTS alembic_version"))


def upgrade(engine: Engine) -> None:
    """Bring the database schema to the newest migration (run at server start)."""
    from alembic import command

    cfg = alembic_config(engine.url.render_as_string(hide_password=False))
    with engine.connect() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "head")
        conn.commit()
