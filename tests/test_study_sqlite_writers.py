"""SQLite writes of one server: writers queue on a lock (not SQLite's busy polling), and a
commit returns only after an fsync of the write-ahead log, one fsync serving many commits."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest
from sqlalchemy import event, text

from cfteach.study import sqlite_writes
from cfteach.study.db import make_engine
from test_study_support import fsyncs_sharing_the_first


def _engine_without_busy_wait(path: Path):  # noqa: ANN202
    """A study engine whose SQLite connections give up at once on a locked database, so
    only the in-process queue can make a second writer wait."""
    engine = make_engine(f"sqlite:///{path}")

    @event.listens_for(engine, "connect")
    def _no_busy_wait(dbapi_conn, _rec):  # noqa: ANN001
        dbapi_conn.execute("PRAGMA busy_timeout=0")

    with engine.begin() as conn:
        conn.execute(text("CREATE TABLE t (n INTEGER)"))
    return engine


def test_concurrent_writers_wait_their_turn(tmp_path: Path) -> None:
    engine = _engine_without_busy_wait(tmp_path / "w.db")
    errors: list[Exception] = []
    start = threading.Barrier(8)

    def writer(k: int) -> None:
        start.wait()
        for i in range(25):
            try:
                with engine.begin() as conn:
                    conn.execute(text("INSERT INTO t VALUES (:n)"), {"n": k * 100 + i})
            except Exception as e:  # noqa: BLE001  (collected and asserted below)
                errors.append(e)

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    with engine.connect() as conn:
        assert conn.scalar(text("SELECT count(*) FROM t")) == 200
    engine.dispose()


def test_the_lock_is_released_by_rollback_and_reads_do_not_take_it(tmp_path: Path) -> None:
    engine = _engine_without_busy_wait(tmp_path / "r.db")
    with pytest.raises(RuntimeError), engine.begin() as conn:
        conn.execute(text("INSERT INTO t VALUES (1)"))
        raise RuntimeError("abort")
    reader = engine.execution_options(readonly=True)
    with reader.connect() as r, r.begin():
        # A read transaction stays open while a writer commits (WAL): no lock between them.
        assert r.scalar(text("SELECT count(*) FROM t")) == 0
        with engine.begin() as conn:
            conn.execute(text("INSERT INTO t VALUES (2)"))
    with engine.connect() as conn:
        assert conn.scalar(text("SELECT n FROM t")) == 2
    engine.dispose()


def test_a_writer_gives_up_after_the_wait_limit(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    engine = _engine_without_busy_wait(tmp_path / "g.db")
    monkeypatch.setattr(sqlite_writes, "WRITE_WAIT_S", 0.05)
    held = threading.Event()
    done = threading.Event()

    def hold() -> None:
        with engine.begin() as conn:
            conn.execute(text("INSERT INTO t VALUES (1)"))
            held.set()
            done.wait(10)

    t = threading.Thread(target=hold)
    t.start()
    held.wait(10)
    with pytest.raises(Exception, match="database is locked .in-process"), engine.begin() as c:
        c.execute(text("INSERT INTO t VALUES (2)"))
    done.set()
    t.join()
    with engine.connect() as conn:
        assert conn.scalar(text("SELECT count(*) FROM t")) == 1
    engine.dispose()


def _wal_sync(engine) -> sqlite_writes.WalSync:  # noqa: ANN001
    with engine.connect() as conn:
        return conn.connection.dbapi_connection.wal_sync


def test_each_write_commit_waits_for_an_fsync_of_the_log(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    engine = _engine_without_busy_wait(tmp_path / "d.db")
    synced: list[str] = []
    real_fsync = os.fsync

    def fsync(fd: int) -> None:
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        real_fsync(fd)

    monkeypatch.setattr(sqlite_writes.os, "fsync", fsync)
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA synchronous").scalar() == 1  # NORMAL + our sync
    for i in range(3):
        with engine.begin() as conn:
            conn.execute(text("INSERT INTO t VALUES (:n)"), {"n": i})
        assert len(synced) == i + 1 and synced[-1] == str((tmp_path / "d.db-wal").resolve())
    with engine.execution_options(readonly=True).begin() as conn:  # reads: no fsync
        conn.execute(text("SELECT count(*) FROM t"))
    assert len(synced) == 3
    engine.dispose()


def test_commits_waiting_together_share_one_fsync(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    engine = _engine_without_busy_wait(tmp_path / "g.db")
    sync = _wal_sync(engine)

    def writer(k: int) -> None:
        with engine.begin() as conn:
            conn.execute(text("INSERT INTO t VALUES (:n)"), {"n": k})

    # the first commit's fsync, then one for the other seven
    assert fsyncs_sharing_the_first(monkeypatch, sync, writer) == 2
    engine.dispose()


def test_a_failed_fsync_fails_the_commit(tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    engine = _engine_without_busy_wait(tmp_path / "f.db")

    def fsync(fd: int) -> None:
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(sqlite_writes.os, "fsync", fsync)
    with pytest.raises(OSError, match="Input/output"), engine.begin() as conn:
        conn.execute(text("INSERT INTO t VALUES (1)"))
    monkeypatch.undo()
    with engine.begin() as conn:  # the next writer is not stuck
        conn.execute(text("INSERT INTO t VALUES (2)"))
    engine.dispose()


_WRITER_SCRIPT = """
import sys
from sqlalchemy import event, text
from cfteach.study.db import durable_barrier, make_engine
engine = make_engine(sys.argv[1])

@event.listens_for(engine, "connect")
def _no_busy_wait(dbapi_conn, _rec):
    dbapi_conn.execute("PRAGMA busy_timeout=0")

for i in range(int(sys.argv[3])):
    with engine.begin() as conn:
        conn.execute(text("INSERT INTO t VALUES (:n)"), {"n": int(sys.argv[2]) * 1000 + i})
        conn.execute(text("SELECT count(*) FROM t")).scalar()  # hold the lock a little
    durable_barrier(engine)  # as a page read does: the other process's commits too
print("done")
"""


def test_writers_of_several_processes_queue_instead_of_failing(tmp_path: Path) -> None:
    """Two processes writing one file with SQLite's busy wait off: each waits for the
    other's commit on the lock beside the database instead of failing 'database is
    locked' (as it did when only threads of one process queued)."""
    import subprocess
    import sys

    engine = _engine_without_busy_wait(tmp_path / "p.db")
    url = f"sqlite:///{tmp_path / 'p.db'}"
    procs = [subprocess.Popen([sys.executable, "-c", _WRITER_SCRIPT, url, str(k), "150"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for k in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [err[-400:] for _, err in outs]
    with engine.connect() as conn:
        assert conn.scalar(text("SELECT count(*) FROM t")) == 300
        assert conn.scalar(text("SELECT count(DISTINCT n) FROM t")) == 300
    engine.dispose()


def test_a_read_waits_for_another_process_commit_to_be_durable(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Engine `b` stands for a second server process on the same file: once `a` has
    committed (visible, its own fsync not finished), `b`'s barrier must fsync the log
    before it answers, though `b` committed nothing; with nothing new, no fsync."""
    a = _engine_without_busy_wait(tmp_path / "x.db")
    b = make_engine(f"sqlite:///{tmp_path / 'x.db'}")
    sync_a, sync_b = _wal_sync(a), _wal_sync(b)
    assert sync_a is not sync_b
    sync_b.barrier()  # b's first fsync records the state it covers
    before = sync_b.fsyncs
    sync_b.barrier()
    assert sync_b.fsyncs == before  # nothing new anywhere: free
    entered, release = threading.Event(), threading.Event()
    real = sqlite_writes.WalSync._fsync

    def fsync(sync: sqlite_writes.WalSync) -> None:
        if sync is sync_a:
            entered.set()
            assert release.wait(10)  # a's commit stays visible but not yet durable
        real(sync)

    monkeypatch.setattr(sqlite_writes.WalSync, "_fsync", fsync)

    def write() -> None:
        with a.begin() as conn:
            conn.execute(text("INSERT INTO t VALUES (7)"))

    t = threading.Thread(target=write)
    t.start()
    assert entered.wait(10)
    with b.connect() as conn:
        assert conn.scalar(text("SELECT count(*) FROM t")) == 1  # b can see it
    sync_b.barrier()
    assert sync_b.fsyncs == before + 1  # a's commit changed the log: b synced it itself
    release.set()
    t.join(10)
    sync_b.barrier()
    assert sync_b.fsyncs == before + 1  # and that fsync covers it
    a.dispose()
    b.dispose()


def test_no_descriptor_of_sqlite_own_files_is_closed_under_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Closing any descriptor of the database or its -shm file drops every POSIX lock
    SQLite holds on it in this process; other processes may then reset the shared index
    under it (a first version that read the -shm header crashed a writer with SIGBUS).
    Writes, fsyncs and barriers open only the log and the ledger beside the database."""
    engine = _engine_without_busy_wait(tmp_path / "o.db")
    opened: list[str] = []
    real_open = os.open

    def spy(path, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        opened.append(str(path))
        return real_open(path, *a, **k)

    monkeypatch.setattr(sqlite_writes.os, "open", spy)
    other = make_engine(f"sqlite:///{tmp_path / 'o.db'}")  # a second ledger is opened
    for i in range(3):
        with engine.begin() as conn:
            conn.execute(text("INSERT INTO t VALUES (:n)"), {"n": i})
        _wal_sync(other).barrier()
    base = str((tmp_path / "o.db").resolve())
    assert opened and set(opened) <= {base + "-wal", base + "-writers"}
    engine.dispose()
    other.dispose()
