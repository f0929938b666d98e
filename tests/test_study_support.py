"""Shared fixtures for the study tests: databases (SQLite, PostgreSQL) and study folders."""

from __future__ import annotations

import functools
import os
import threading
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import create_engine, make_url, text

from cfteach.study.build import init_study, toy_sources
from cfteach.study.db import drop_schema, make_engine

PG_ENV = "CFTEACH_TEST_POSTGRES_URL"


def postgres_url() -> str:
    """The test PostgreSQL URL; fails loudly in CI when it is missing, else skips.

    Under pytest-xdist each worker gets its own database on the one server
    (`<name>_gw0`, `<name>_gw1`, ...), so one worker's `drop_schema` never pulls the tables
    from under another's test."""
    url = os.environ.get(PG_ENV)
    if not url:
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail(f"{PG_ENV} is not set: run `source scripts/postgres-for-tests` "
                        "(scripts/test does) so the PostgreSQL tests run in CI")
        pytest.skip(f"{PG_ENV} not set (outside CI); `source scripts/postgres-for-tests`")
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    return _worker_database(url, worker) if worker else url


@functools.cache
def _worker_database(url: str, worker: str) -> str:
    """The URL of this worker's own database on the server of `url`, created if missing."""
    base = make_url(url)
    name = f"{base.database}_{worker}"
    admin = create_engine(base, isolation_level="AUTOCOMMIT")
    try:
        with admin.connect() as conn:
            exists = conn.execute(text("SELECT 1 FROM pg_database WHERE datname = :n"),
                                  {"n": name}).scalar()
            if not exists:
                conn.execute(text(f'CREATE DATABASE "{name}"'))
    finally:
        admin.dispose()
    return base.set(database=name).render_as_string(hide_password=False)


def fresh_postgres() -> str:
    url = postgres_url()
    engine = make_engine(url)
    drop_schema(engine)
    engine.dispose()
    return url


@pytest.fixture(scope="session")
def toy_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A three-domain toy study with 2 short demos per condition and 6 tests per domain.

    15 ms per demonstration step: every toy replay (9 to 13 steps) is shorter than the
    server's tolerance, so bots need not wait (tests of the timing use their own study)."""
    out = tmp_path_factory.mktemp("toy_study")
    init_study(out, toy_sources(), demo_step_ms=15, completion_code="C0MPL3TE",
               screened_out_code="SCR33N")
    return out


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """Every API test runs on SQLite and on a real PostgreSQL server."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'study.db'}"
    return fresh_postgres()


def test_toy_study_is_complete(toy_study: Path) -> None:
    import json

    s = json.loads((toy_study / "study.json").read_text())
    assert s["domains"] == ["toy_a", "toy_b", "toy_c"]
    assert all(len(ts) == 6 for d in s["domains"] for ts in s["tests"][d])
    # Each test set has 2 tests of each difficulty, and test ids are unique in the study.
    for d in s["domains"]:
        for ts in s["tests"][d]:
            assert sorted(t["difficulty"] for t in ts) == ["high"] * 2 + ["low"] * 2 + [
                "medium"] * 2
    ids = [t["test_id"] for d in s["domains"] for ts in s["tests"][d] for t in ts]
    assert len(ids) == len(set(ids)) == 54


def session_state(c: TestClient, token: str) -> dict:
    """The participant's `/api/state`, asserting the server answered 200."""
    r = c.get("/api/state", headers={"X-Session-Token": token})
    assert r.status_code == 200, r.text
    return r.json()


def researcher_progress(c: TestClient, researcher_token: str = "rt") -> dict:
    """The researcher's `/api/researcher/progress` view."""
    return c.get("/api/researcher/progress",
                 headers={"X-Researcher-Token": researcher_token}).json()


def fsyncs_sharing_the_first(monkeypatch: pytest.MonkeyPatch, sync, work,  # noqa: ANN001
                             n: int = 8, seconds: float = 10.0) -> int:
    """Run `work(k)` for k < n in threads, each one write commit: the first alone, the
    others once its WAL fsync (of `sync`, a `sqlite_writes.WalSync`) has started, which
    lasts until all n have committed (at most `seconds`). Returns the fsyncs they took: 2
    when the n - 1 others shared the one after the first's; n when each waited its turn."""
    from cfteach.study import sqlite_writes

    real_fsync = os.fsync
    first = threading.Event()
    base, fsyncs = sync.committed, sync.fsyncs

    def fsync(fd: int) -> None:
        if not first.is_set():
            first.set()
            for _ in range(int(seconds * 100)):
                if sync.committed >= base + n:
                    break
                threading.Event().wait(0.01)
        real_fsync(fd)

    monkeypatch.setattr(sqlite_writes.os, "fsync", fsync)
    threads = [threading.Thread(target=work, args=(k,)) for k in range(n)]
    threads[0].start()
    first.wait(10)
    for t in threads[1:]:
        t.start()
    for t in threads:
        t.join()
    assert sync.committed == sync.durable == base + n
    return sync.fsyncs - fsyncs
