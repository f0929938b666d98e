"""The SQLite write path of one server process: writers take turns, commits share fsyncs.

Two things made SQLite slow under many participants at once (bench/bench_study_load.py,
profiled with py-spy):

- Writers polled for SQLite's lock with growing sleeps (its busy handler: 1, 2, 5 ... 100 ms),
  unfairly: some waited seconds while the lock was mostly free. Here the threads of one
  process queue on a Python lock that hands over at once (other processes still meet
  SQLite's busy timeout).
- `synchronous=FULL` fsyncs the write-ahead log inside every commit, so at most one commit
  per fsync (4-8 ms here) went through. SQLite's documentation defines FULL in WAL mode as
  NORMAL plus "an additional sync operation of the WAL file after each transaction commit";
  we run NORMAL and do that sync ourselves, after the write lock is released, and one fsync
  serves every commit that finished before it started (group commit). `commit()` still
  returns only once the log is on disk, so an event is acknowledged only when it is durable.

Several server processes may share one database file (docs/study.md, "Several server
processes"): each process's queued writer also takes an exclusive `flock` on
``<db>-writers``, which the kernel hands over at once, and a read that must answer only what
is durable (`WalSync.barrier`) compares the log's index header, which every commit of every
process changes, with the one an fsync of this process started from.
"""

from __future__ import annotations

import os
import sqlite3
import threading

try:
    import fcntl
except ImportError:  # Windows: one server process per database file
    fcntl = None  # type: ignore[assignment]

WRITE_WAIT_S = 30.0  # as SQLite's busy_timeout: then "database is locked"
#: The WAL index header (https://www.sqlite.org/walformat.html, "The WAL-Index Header"):
#: 48 bytes at the start of the -shm file; its frame count, salts and checksums change with
#: every commit and every restart of the log, whichever process made them.
WAL_INDEX_HEADER_BYTES = 48


class NotDurable(OSError):
    """A commit is visible but its fsync failed: the request must not be answered as stored
    nor as failed (the server answers 503 and the page retries; the retry's 409 confirms
    it once an fsync succeeds)."""


class WalSync:
    """Makes commits durable with as few fsyncs of the WAL file as possible."""

    def __init__(self, db_path: str) -> None:
        self.db_path, self.wal_path = db_path, db_path + "-wal"
        self._cond = threading.Condition()
        self.committed = 0  # write commits counted so far
        self.durable = 0  # of those, how many a finished fsync covers
        self.fsyncs = 0
        self.in_flight = 0  # COMMITs running now (visible to readers before they count)
        self._syncing = False
        self.shm_path = db_path + "-shm"
        self._synced_header: bytes | None = None  # the log's state when the last fsync began

    def begin_commit(self) -> None:
        """Call right before a write transaction's COMMIT."""
        with self._cond:
            self.in_flight += 1

    def abort_commit(self) -> None:
        with self._cond:
            self.in_flight -= 1

    def barrier(self) -> None:
        """Return once every commit a read made now could see is on disk (for answers that
        report stored data: a 409 duplicate, a page read). Free when all are already."""
        with self._cond:
            here = self.in_flight == 0 and self.durable >= self.committed
            synced = self._synced_header
        if here and synced is not None and self.log_state() == synced:
            return  # nothing committed, by any process, since an fsync began
        self.wait_durable(after_commit=False)

    def log_state(self) -> bytes | None:
        """The WAL index header now (None when there is no index to read)."""
        try:
            fd = os.open(self.shm_path, os.O_RDONLY)
        except OSError:
            return None
        try:
            head = os.pread(fd, WAL_INDEX_HEADER_BYTES, 0)
        finally:
            os.close(fd)
        return head if len(head) == WAL_INDEX_HEADER_BYTES else None

    def wait_durable(self, *, after_commit: bool = True) -> None:
        """Call right after a write transaction's COMMIT; returns once it is on disk.
        Raises `NotDurable` if the fsync fails (the commit is visible all the same)."""
        with self._cond:
            if after_commit:
                self.in_flight -= 1
            self.committed += 1
            mine = self.committed
            while self.durable < mine:
                if self._syncing:  # a sync is running; it may have started before us
                    self._cond.wait()
                    continue
                self._syncing, upto = True, self.committed
                try:
                    self._cond.release()
                    try:
                        state = self.log_state()  # before the fsync: what it will cover
                        self._fsync()
                    except OSError as e:
                        raise NotDurable(f"fsync of {self.wal_path} failed: {e}") from e
                    finally:
                        self._cond.acquire()
                    self.durable = max(self.durable, upto)
                    self._synced_header = state
                finally:
                    self._syncing = False
                    self._cond.notify_all()

    def _fsync(self) -> None:
        # Opened each time: SQLite may delete and recreate the log (last connection closed).
        try:
            fd = os.open(self.wal_path, os.O_RDONLY)
        except FileNotFoundError:  # checkpointed into the database file and removed
            fd = os.open(self.db_path, os.O_RDONLY)
        try:
            os.fsync(fd)
            self.fsyncs += 1
        finally:
            os.close(fd)


def connection_class(sync: WalSync | None) -> type[sqlite3.Connection]:
    """A sqlite3 connection class for one engine: queued writers, and durable commits
    through `sync` (None: SQLite syncs by itself, synchronous=FULL)."""
    lock = threading.Lock()
    between_processes = (ProcessWriterLock(sync.db_path + "-writers")
                         if sync is not None and fcntl is not None else None)

    class QueuedWriters(sqlite3.Connection):
        wal_sync = sync
        holds_write_lock = False

        def wait_for_write_lock(self) -> None:
            if not lock.acquire(timeout=WRITE_WAIT_S):
                raise sqlite3.OperationalError("database is locked (in-process writers)")
            try:
                if between_processes is not None:
                    between_processes.acquire()
            except BaseException:
                lock.release()
                raise
            self.holds_write_lock = True

        def release_write_lock(self) -> None:
            if self.holds_write_lock:
                self.holds_write_lock = False
                try:
                    if between_processes is not None:
                        between_processes.release()
                finally:
                    lock.release()

        def commit(self) -> None:
            wal = sync if self.holds_write_lock else None  # a write to make durable
            if wal is not None:
                wal.begin_commit()
            try:
                super().commit()
            except BaseException:
                if wal is not None:
                    wal.abort_commit()
                raise
            finally:
                self.release_write_lock()
            if wal is not None:
                wal.wait_durable()

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


class ProcessWriterLock:
    """An exclusive `flock` on a file beside the database, taken by the one writer of this
    process that holds the in-process lock: writers of several server processes queue in
    the kernel, which wakes the next one when the lock is released (SQLite's own busy
    handler sleeps 1, 2, 5 ... 100 ms between tries). The kernel drops it if the process
    dies, so a crash never leaves the database locked."""

    def __init__(self, path: str) -> None:
        self.path = path
        self._fd: int | None = None

    def acquire(self) -> None:
        if self._fd is None:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
        fcntl.flock(self._fd, fcntl.LOCK_EX)  # blocks without holding the interpreter lock

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)

    def __del__(self) -> None:  # one per engine: closed with it, not kept for the process
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
