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
``<db>-writers``, which the kernel hands over at once, and numbers its commit in that file
(`CommitLedger`), so a read that must answer only what is durable (`WalSync.barrier`) knows
whether another process has committed since this process's last fsync began. (Only our own
file is opened: closing any descriptor of the database or its `-shm` file would drop
SQLite's POSIX locks of the whole process.)
"""

from __future__ import annotations

import os
import sqlite3
import struct
import threading

try:
    import fcntl
except ImportError:  # Windows: one server process per database file
    fcntl = None  # type: ignore[assignment]

WRITE_WAIT_S = 30.0  # as SQLite's busy_timeout: then "database is locked"
#: Each count in the ledger is stored with its complement: a torn read is seen as such.
_CHECK = 0x5A5A_5A5A_5A5A_5A5A


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
        # Commits of every process sharing the file (None where flock is missing: Windows)
        self.ledger = CommitLedger(db_path + "-writers") if fcntl is not None else None
        self._synced_upto = -1  # ledger: commits finished before this process's last fsync

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
            synced = self._synced_upto
        if here and (self.ledger is None or self.ledger.started() <= synced):
            return  # nothing committed, by any process, since an fsync of ours began
        self.wait_durable(after_commit=False)

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
                        # before the fsync: the other processes' commits it will cover
                        finished = self.ledger.finished() if self.ledger else -1
                        self._fsync()
                    except OSError as e:
                        raise NotDurable(f"fsync of {self.wal_path} failed: {e}") from e
                    finally:
                        self._cond.acquire()
                    self.durable = max(self.durable, upto)
                    self._synced_upto = max(self._synced_upto, finished)
                finally:
                    self._syncing = False
                    self._cond.notify_all()

    def _fsync(self) -> None:
        # Opened each time: SQLite may delete and recreate the log (last connection closed).
        # Never the database file itself: closing a descriptor of it would drop SQLite's
        # locks on it. A missing log was checkpointed, and SQLite synced the database then.
        try:
            fd = os.open(self.wal_path, os.O_RDONLY)
        except FileNotFoundError:
            self.fsyncs += 1
            return
        try:
            os.fsync(fd)
            self.fsyncs += 1
        finally:
            os.close(fd)


def connection_class(sync: WalSync | None) -> type[sqlite3.Connection]:
    """A sqlite3 connection class for one engine: queued writers, and durable commits
    through `sync` (None: SQLite syncs by itself, synchronous=FULL)."""
    lock = threading.Lock()
    between_processes = sync.ledger if sync is not None else None

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
            ledger = between_processes if self.holds_write_lock else None
            if wal is not None:
                wal.begin_commit()
            try:
                n = ledger.start() if ledger is not None else 0  # before it can be seen
                try:
                    super().commit()
                finally:
                    if ledger is not None:
                        ledger.finish(n)
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


class CommitLedger:
    """The file beside the database that the server processes sharing it write through.

    An exclusive `flock` on it is the writers' lock: taken by the one writer of this process
    that holds the in-process lock, so the writers of several processes queue in the kernel,
    which wakes the next one when it is released (SQLite's own busy handler sleeps 1, 2, 5
    ... 100 ms between tries); the kernel drops it if the process dies, but it has no time
    limit: a process stopped (not killed) inside a write stalls the others' writes until it
    runs again, where SQLite's busy timeout would have failed them. Under that lock each
    writer numbers its commit: *started* n before its COMMIT, *finished* n after it. A commit
    another process can see has started; an fsync covers every commit finished before it
    began. The counts need no fsync: they only coordinate the processes running now."""

    def __init__(self, path: str) -> None:
        self.path = path
        self._fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)

    def acquire(self) -> None:
        fcntl.flock(self._fd, fcntl.LOCK_EX)  # blocks without holding the interpreter lock

    def release(self) -> None:
        fcntl.flock(self._fd, fcntl.LOCK_UN)

    def _read(self) -> tuple[int, int] | None:
        raw = os.pread(self._fd, 32, 0)
        if not raw:
            return 0, 0  # a new file: nothing committed through it yet
        if len(raw) != 32:
            return None
        s, s_check, f, f_check = struct.unpack("<4Q", raw)
        return (s, f) if s ^ _CHECK == s_check and f ^ _CHECK == f_check else None

    def started(self) -> int:
        """The last commit started by any process (a torn read counts as a new commit)."""
        counts = self._read()
        return 2**63 if counts is None else counts[0]

    def finished(self) -> int:
        """The last commit finished by any process (-1 after a torn read: none known)."""
        counts = self._read()
        return -1 if counts is None else counts[1]

    def start(self) -> int:
        """Under the lock: number the next commit (after a writer that died mid-commit too)."""
        counts = self._read()
        # Unreadable even under the lock (a damaged file): jump far ahead of any count a
        # running process may have seen, so none takes a later commit for a synced one.
        n = max(counts) + 1 if counts is not None else 2**62
        os.pwrite(self._fd, struct.pack("<2Q", n, n ^ _CHECK), 0)
        return n

    def finish(self, n: int) -> None:
        os.pwrite(self._fd, struct.pack("<2Q", n, n ^ _CHECK), 16)

    def __del__(self) -> None:  # one per engine: closed with it, not kept for the process
        fd, self._fd = getattr(self, "_fd", -1), -1
        if fd >= 0:
            os.close(fd)
