"""One session per Prolific participant per study (issue 22, item 1): keyed on the study's
own key written at `study init`, whatever STUDY_ID the link carries; a finished
participant gets the page for that status; `analyze` refuses two sessions of one
participant unless told which to keep."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from fastapi.testclient import TestClient

import test_study_support
from cfteach.study import create_app, export_csv
from cfteach.study.bot import run_participant
from cfteach.study.build import init_study, toy_sources

toy_study = test_study_support.toy_study
db_url = test_study_support.db_url


def _start(c: TestClient, pid: str, study_id: str | None, session_id: str | None) -> dict:
    body = {"prolific_pid": pid}
    if study_id is not None:
        body["study_id"] = study_id
    if session_id is not None:
        body["session_id"] = session_id
    return c.post("/api/session", json=body)


def test_study_init_writes_a_key_outside_the_version_and_keeps_it(tmp_path: Path) -> None:
    init_study(tmp_path / "a", toy_sources())
    first = json.loads((tmp_path / "a" / "study.json").read_text())
    init_study(tmp_path / "a", toy_sources())  # the same folder again: the same study
    again = json.loads((tmp_path / "a" / "study.json").read_text())
    init_study(tmp_path / "b", toy_sources())
    other = json.loads((tmp_path / "b" / "study.json").read_text())
    assert len(first["study_key"]) == 16 and again["study_key"] == first["study_key"]
    assert other["study_key"] != first["study_key"]
    assert other["version"] == first["version"]  # the key is not part of the content


def test_screened_out_participant_cannot_start_again(toy_study: Path, db_url: str) -> None:
    app = create_app(toy_study, db_url, seed=1, sessions_per_minute=0)
    with TestClient(app) as c:
        r = _start(c, "PIDSCREEN1", "STUDY_A", "SESS1")
        token, pid0 = r.json()["token"], r.json()["participant_id"]
        out = run_participant(c, None, token=token, fail_practice=True)
        assert out["state"]["status"] == "screened_out"
        # another STUDY_ID, none, another SESSION_ID, no token: the same (finished) session
        for study_id, sess in (("STUDY_B", "SESS2"), (None, None), ("STUDY_A", "SESS3")):
            r = _start(c, "PIDSCREEN1", study_id, sess)
            assert r.status_code == 200, r.text
            assert r.json()["participant_id"] == pid0 and r.json()["resumed"] is True
            st = c.get("/api/state", headers={"X-Session-Token": r.json()["token"]}).json()
            assert st["status"] == "screened_out" and st["step"]["kind"] == "screened_out"
            assert st["step"]["code"] == "SCR33N"
    app2 = create_app(toy_study, db_url, researcher_token="rt")
    with TestClient(app2) as c2:
        prog = c2.get("/api/researcher/progress", headers={"X-Researcher-Token": "rt"}).json()
    assert prog["status"] == {"screened_out": 1}, prog


def test_declined_and_completed_get_their_page(toy_study: Path, db_url: str) -> None:
    app = create_app(toy_study, db_url, seed=2, sessions_per_minute=0)
    with TestClient(app) as c:
        r = _start(c, "PIDDECLINE", "S1", "X1")
        h = {"X-Session-Token": r.json()["token"]}
        r = c.post("/api/event", headers=h, json={"event_id": "evdecline1", "step_index": 0,
                                                  "type": "decline", "payload": {}})
        assert r.status_code == 200, r.text
        r = _start(c, "PIDDECLINE", "S2", "X2")
        st = c.get("/api/state", headers={"X-Session-Token": r.json()["token"]}).json()
        assert st["status"] == "declined" and st["step"]["kind"] == "declined"
        r = _start(c, "PIDDONE", "S1", "X1")
        run_participant(c, None, token=r.json()["token"])
        r = _start(c, "PIDDONE", "OTHER", "X9")
        st = c.get("/api/state", headers={"X-Session-Token": r.json()["token"]}).json()
        assert st["status"] == "completed" and st["step"]["kind"] == "complete"


def test_unfinished_session_is_not_open_to_another_study_id(toy_study: Path,
                                                           db_url: str) -> None:
    app = create_app(toy_study, db_url, seed=3, sessions_per_minute=0)
    with TestClient(app) as c:
        first = _start(c, "PIDBUSY1", "S1", "X1").json()
        r = _start(c, "PIDBUSY1", "S2", "X2")  # no proof: refused, nothing created
        assert r.status_code == 409 and r.json()["error"] == "session_elsewhere"
        r = _start(c, "PIDBUSY1", "S2", "X1")  # its own SESSION_ID: the same session
        assert r.status_code == 200 and r.json()["participant_id"] == first["participant_id"]


def test_analyze_refuses_two_sessions_of_one_participant(tmp_path: Path) -> None:
    from cfteach.analysis import (
        ExportError,
        SyntheticConfig,
        generate,
        load_export,
        write_export,
    )

    d = tmp_path / "export"
    write_export(generate(SyntheticConfig(n_participants=16, seed=0)), d)
    parts = pd.read_csv(d / "participants.csv", dtype=str, keep_default_na=False)
    ids = list(parts["participant_id"])
    parts["prolific_pid"] = [f"P{k}" for k in range(len(parts))]
    parts.loc[1, "prolific_pid"] = "P0"  # two sessions of one participant
    parts.to_csv(d / "participants.csv", index=False)
    with pytest.raises(ExportError, match=r"prolific_pid 'P0'.*2 sessions") as e:
        load_export(d)
    assert ids[0] in str(e.value) and ids[1] in str(e.value)
    kept = load_export(d, keep_sessions=[ids[1]])
    assert ids[0] not in set(kept.participants["participant_id"])
    assert ids[1] in set(kept.participants["participant_id"])
    assert ids[0] not in set(kept.tests["participant_id"])
    with pytest.raises(ExportError, match="not in participants.csv"):
        load_export(d, keep_sessions=["nope"])


def test_export_then_analyze_sees_one_session(toy_study: Path, tmp_path: Path) -> None:
    """End to end: the server never makes the second session the review found."""
    db = f"sqlite:///{tmp_path / 'e.db'}"
    app = create_app(toy_study, db, seed=4, sessions_per_minute=0)
    with TestClient(app) as c:
        tok = _start(c, "PIDTWICE", "A", "X").json()["token"]
        run_participant(c, None, token=tok)
        _start(c, "PIDTWICE", "B", "Y")
    export_csv(db, tmp_path / "out")
    parts = pd.read_csv(tmp_path / "out" / "participants.csv", dtype=str)
    assert list(parts["prolific_pid"]) == ["PIDTWICE"]
