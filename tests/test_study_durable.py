"""Durability and strictness on every path (issue 22, items 4, 9, 10): a 409 duplicate and
a page read answer only what is on disk; a failed fsync answers 503 (not 500) and the
retry confirms; NaN and Infinity are refused on every route and never written to an
export; PostgreSQL must commit synchronously; a half-sent body is timed out."""

from __future__ import annotations

import csv
import json
import socket
import threading
import time
import uuid
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

import test_study_support
from cfteach.study import create_app, export_csv
from cfteach.study.config import StudyError
from cfteach.study.livesrv import running
from cfteach.study.sqlite_writes import WalSync

toy_study = test_study_support.toy_study


class HeldFsync:
    """Makes WalSync's fsync wait for `release` while `hold` is set (commits stay visible
    but not durable), or fail while `fail` counts down."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.hold, self.release, self.entered = False, threading.Event(), threading.Event()
        self.fail = 0
        real = WalSync._fsync

        def fsync(sync: WalSync) -> None:
            if self.fail > 0:
                self.fail -= 1
                raise OSError(5, "Input/output error")
            if self.hold:
                self.entered.set()
                assert self.release.wait(30)
            real(sync)

        monkeypatch.setattr(WalSync, "_fsync", fsync)


def _event(c: TestClient, tok: str, eid: str, step: int = 0, type_: str = "consent",
           payload: dict | None = None):  # noqa: ANN202
    payload = {"adult": True, "read": True, "agree": True} if payload is None else payload
    return c.post("/api/event", headers={"X-Session-Token": tok}, json={
        "event_id": eid, "step_index": step, "type": type_, "payload": payload})


def test_duplicate_and_page_wait_for_the_disk(toy_study: Path, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    held = HeldFsync(monkeypatch)
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'd.db'}", seed=1)
    with TestClient(app) as c:
        tok = c.post("/api/session", json={"prolific_pid": "DURABLE01"}).json()["token"]
        held.hold = True
        eid = uuid.uuid4().hex
        first: dict = {}
        t1 = threading.Thread(target=lambda: first.update(r=_event(c, tok, eid)))
        t1.start()
        assert held.entered.wait(10)  # committed (visible), fsync not finished
        answers: dict = {}
        t2 = threading.Thread(target=lambda: answers.update(dup=_event(c, tok, eid)))
        t3 = threading.Thread(target=lambda: answers.update(page=c.get(
            "/api/state", headers={"X-Session-Token": tok})))
        t2.start()
        t3.start()
        time.sleep(0.6)
        assert answers == {}  # neither the 409 nor the page may answer before the disk
        held.hold = False
        held.release.set()
        for t in (t1, t2, t3):
            t.join(10)
        assert first["r"].status_code == 200
        assert answers["dup"].status_code == 409
        assert answers["dup"].json()["error"] == "duplicate_event"
        assert answers["page"].json()["step_index"] == 1


def test_failed_fsync_answers_503_and_the_retry_confirms(
        toy_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    held = HeldFsync(monkeypatch)
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'f.db'}", seed=2)
    with TestClient(app, raise_server_exceptions=False) as c:
        tok = c.post("/api/session", json={"prolific_pid": "FSYNCFAIL1"}).json()["token"]
        eid = uuid.uuid4().hex
        held.fail = 1
        r = _event(c, tok, eid)
        assert r.status_code == 503 and r.json()["error"] == "not_durable"
        assert r.headers["retry-after"] == "1"
        r = _event(c, tok, eid)  # the page's retry: stored once, now on disk
        assert r.status_code == 409 and r.json()["error"] == "duplicate_event"
        st = c.get("/api/state", headers={"X-Session-Token": tok}).json()
        assert st["step_index"] == 1


@pytest.mark.parametrize("raw", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_numbers_are_refused_everywhere(toy_study: Path, tmp_path: Path,
                                                   raw: str) -> None:
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'n.db'}", seed=3)
    hdr = {"content-type": "application/json"}
    with TestClient(app, raise_server_exceptions=False) as c:
        tok = c.post("/api/session", json={"prolific_pid": "NANPID01"}).json()["token"]
        rid, eid = uuid.uuid4().hex, uuid.uuid4().hex
        report = ('{"report_id": "' + rid + '", "path": "/api/event", "http_status": 422, '
                  '"error": "x", "detail": "y", "client_ms": ' + raw + '}')
        event = ('{"event_id": "' + eid + '", "step_index": 0, "type": "page_load", '
                 '"payload": {}, "client_ms": ' + raw + '}')
        nested = ('{"event_id": "' + eid + '", "step_index": 0, "type": "page_load", '
                  '"payload": {"x": [1, ' + raw + ']}}')
        session = '{"prolific_pid": "NANPID02", "mode": ' + raw + '}'
        for path, body, h in (("/api/client-report", report, hdr),
                              ("/api/event", event, {**hdr, "X-Session-Token": tok}),
                              ("/api/event", nested, {**hdr, "X-Session-Token": tok}),
                              ("/api/session", session, hdr)):
            r = c.post(path, content=body, headers=h)
            assert r.status_code == 422, (path, r.status_code, r.text)
            assert r.json()["error"] == "bad_request" and "finite" in r.json()["detail"]
        r = c.post("/api/event", headers=hdr | {"X-Session-Token": tok},
                   content=event.replace(raw, "12.5"))
        assert r.status_code == 200  # the same body with a number is fine


def test_export_writes_strict_json_for_old_rows(toy_study: Path, tmp_path: Path) -> None:
    """Rows stored before the server refused NaN are exported as null, never as NaN."""
    from cfteach.study.models import ClientReport, utcnow

    db = f"sqlite:///{tmp_path / 'x.db'}"
    app = create_app(toy_study, db, seed=4)
    with app.state.service.Session() as s, s.begin():
        s.add(ClientReport(report_id="r" * 16, session_pk=None, path="/api/event",
                           http_status=422, error="x", detail="y",
                           event={"type": "page_load", "client_ms": float("nan"),
                                  "payload": {"v": float("inf")}},
                           client_ms=float("nan"), server_at=utcnow()))
    export_csv(db, tmp_path / "out")
    with open(tmp_path / "out" / "client_reports.csv", newline="") as f:
        rows = list(csv.DictReader(f))

    def strict(name: str) -> None:
        raise ValueError(name)

    assert len(rows) == 1
    event = json.loads(rows[0]["event"], parse_constant=strict)
    assert event["client_ms"] is None and event["payload"] == {"v": None}


@pytest.mark.postgres
def test_synchronous_commit_off_is_refused(toy_study: Path) -> None:
    url = test_study_support.fresh_postgres()
    sep = "&" if "?" in url else "?"
    off = f"{url}{sep}options=-csynchronous_commit%3Doff"
    with pytest.raises(StudyError, match="synchronous_commit=off"):
        create_app(toy_study, off)
    app = create_app(toy_study, off, allow_async_commit=True)
    app.state.service.engine.dispose()


def test_half_sent_body_is_timed_out(toy_study: Path, tmp_path: Path) -> None:
    app = create_app(toy_study, f"sqlite:///{tmp_path / 't.db'}", body_timeout_s=0.5)
    with running(app) as base:
        port = int(base.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
            s.sendall(b"POST /api/session HTTP/1.1\r\nHost: x\r\n"
                      b"Content-Type: application/json\r\nContent-Length: 100\r\n\r\n{\"pro")
            t0 = time.monotonic()
            chunks = [s.recv(4096)]
            waited = time.monotonic() - t0
            while chunks[-1]:  # the server closes the connection after the answer
                chunks.append(s.recv(4096))
            reply = b"".join(chunks).decode()
    assert reply.startswith("HTTP/1.1 408"), reply[:200]
    assert "body_timeout" in reply and waited < 5
