"""Engines and migrations: SQLite (WAL, durable commits) by default, PostgreSQL by URL."""

from __future__ import annotations

import weakref
from pathlib import Path

from sqlalchemy import Engine, create_engine, event, make_url, text

from .sqlite_writes import WalSync, connection_class

HERE = Path(__file__).parent
_SYNCS: weakref.WeakKeyDictionary[Engine, WalSync] = weakref.WeakKeyDictionary()

#: PostgreSQL connections a server keeps open, and how many more it may open for a burst.
#: The request threads (anyio's 40) are the most that use the database at once, so 30 + 10
#: never makes a request wait for a connection. A connection beyond the pool is closed when
#: it is returned: with a pool of 10, 200 participants made a server open a new connection
#: (PostgreSQL starts a backend process for each) about 10 times a second, and PostgreSQL
#: used twice the CPU (docs/study.md, "Load"). The most recently returned connection is
#: used first (LIFO), so a quiet study keeps few backends busy. Each server holds up to 40
#: of PostgreSQL's `max_connections` (100 by default).
PG_POOL_SIZE, PG_POOL_OVERFLOW = 30, 10
PG_POOL_LIFO = True


def durable_barrier(engine: Engine) -> None:
    """Return once whatever a read of `engine` can see now is on disk. SQLite (group
    commit, sqlite_writes) shows a commit a few ms before its fsync; PostgreSQL with
    `synchronous_commit` on (checked at start: `check_synchronous_commit`) never does."""
    sync = _SYNCS.get(engine)
    if sync is not None:
        sync.barrier()


def check_synchronous_commit(engine: Engine, *, allow_off: bool = False) -> str | None:
    """PostgreSQL's `synchronous_commit` for the study's connections; raise ValueError if
    it is ``off`` (a commit, hence an acknowledged answer, could then be lost in a crash)
    unless `allow_off`. None on SQLite."""
    if engine.dialect.name != "postgresql":
        return None
    with engine.connect() as conn:
        value = str(conn.exec_driver_sql("SHOW synchronous_commit").scalar())
    if value == "off" and not allow_off:
        raise ValueError("PostgreSQL runs with synchronous_commit=off: an acknowledged answer "
                         "could be lost in a crash. Set it to on for this database (ALTER "
                         "DATABASE ... SET synchronous_commit = on) or pass "
                         "--allow-async-commit to run anyway")
    return value


def make_engine(url: str) -> Engine:
    """An engine with the durability settings the study needs."""
    if url.startswith("sqlite"):
        path = make_url(url).database
        # A file: NORMAL + our own WAL fsync after each commit, shared by concurrent commits
        # (the durability of FULL; see sqlite_writes). In memory: nothing to sync.
        sync = WalSync(str(Path(path).resolve())) if path and path != ":memory:" else None
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30,
                                                  "factory": connection_class(sync)})
        if sync is not None:
            _SYNCS[engine] = sync

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn, _rec):  # noqa: ANN001
            dbapi_conn.isolation_level = None  # we emit BEGIN ourselves (below)
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute(f"PRAGMA synchronous={'NORMAL' if sync else 'FULL'}")
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
        return create_engine(url, pool_size=PG_POOL_SIZE, max_overflow=PG_POOL_OVERFLOW,
                             pool_use_lifo=PG_POOL_LIFO, pool_pre_ping=True)
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
