"""/api/client-report: where the page leaves a request the server refused for good.

The page keeps a refused event until this endpoint has stored it, so the report must be
idempotent (a retried report is stored once), work without a valid session (the session
may be what failed), stay bounded, and reach the researcher through the export.
"""

from __future__ import annotations

import csv
import json
import uuid
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

import test_study_support
from cfteach.study.export import export_csv
from cfteach.study.server import create_app

db_url = test_study_support.db_url
toy_study = test_study_support.toy_study

PARAMS = {"prolific_pid": "5f1c0ffee0ddba11c0ffee01", "study_id": "S1", "session_id": "X1"}


@pytest.fixture
def client(toy_study: Path, db_url: str) -> TestClient:
    app = create_app(toy_study, db_url, seed=2, reports_per_minute=5)
    with TestClient(app) as c:
        yield c
    app.state.service.engine.dispose()


def _read(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _refused_event(c: TestClient, token: str) -> tuple[dict, dict]:
    """A test answer sent on the consent page: refused for good (422 wrong_event_type)."""
    ev = {"event_id": uuid.uuid4().hex, "step_index": 0, "type": "test_response",
          "payload": {"actions": ["up"], "time_ms": 5, "confidence": 3}}
    r = c.post("/api/event", headers={"X-Session-Token": token}, json=ev)
    assert r.status_code == 422
    return ev, r.json()


def test_a_refused_event_is_stored_once_and_exported(client: TestClient, db_url: str,
                                                     tmp_path: Path) -> None:
    token = client.post("/api/session", json=PARAMS).json()["token"]
    ev, answer = _refused_event(client, token)
    body = {"report_id": ev["event_id"], "path": "/api/event", "http_status": 422,
            "error": answer["error"], "detail": answer["detail"], "event": ev,
            "client_ms": 1.7e12}
    for _ in range(2):  # the page retries until it has an answer: stored once
        r = client.post("/api/client-report", headers={"X-Session-Token": token}, json=body)
        assert r.status_code == 200 and r.json()["ok"] is True
    assert r.json()["duplicate"] is True
    # A report from a page without a (valid) session is kept too.
    r = client.post("/api/client-report", headers={"X-Session-Token": "gone"}, json={
        "report_id": uuid.uuid4().hex, "path": "/api/state", "http_status": 401,
        "error": "no_session", "detail": "unknown session token"})
    assert r.status_code == 200
    export_csv(db_url, tmp_path)
    (p,) = _read(tmp_path / "participants.csv")
    rows = _read(tmp_path / "client_reports.csv")
    assert [(r["participant_id"], r["path"], r["http_status"], r["error"]) for r in rows] == [
        (p["participant_id"], "/api/event", "422", "wrong_event_type"),
        ("", "/api/state", "401", "no_session")]
    assert rows[0]["event_type"] == "test_response" and rows[0]["step_index"] == "0"
    assert json.loads(rows[0]["event"]) == ev
    assert rows[0]["detail"] == answer["detail"]
    # The refused answer changed nothing in the participant's data.
    assert _read(tmp_path / "test_responses.csv") == []
    described = {r["column"] for r in _read(tmp_path / "data_dictionary.csv")
                 if r["file"] == "client_reports.csv"}
    assert described == set(rows[0])


def test_reports_are_validated_and_rate_limited(client: TestClient) -> None:
    good = {"report_id": uuid.uuid4().hex, "path": "/api/event", "http_status": 400}
    for bad in ({**good, "report_id": "x"}, {**good, "http_status": 700},
                {**good, "detail": "x" * 2001}, {**good, "extra": 1}, {"path": "/"}):
        r = client.post("/api/client-report", json=bad)
        assert r.status_code == 422 and r.json()["error"] == "bad_request", bad
    codes = [client.post("/api/client-report", json={**good, "report_id": uuid.uuid4().hex},
                         headers={"X-Session-Token": uuid.uuid4().hex}).status_code
             for _ in range(7)]
    assert codes == [200] * 5 + [429] * 2  # per client address, whatever token is sent
