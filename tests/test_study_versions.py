"""A changed study file strands nobody: sessions finish on the version they started with
(kept in the database), and sessions on a version the database does not hold block a
restart on a new file unless the researcher says `--new-version`. SQLite and PostgreSQL."""

from __future__ import annotations

import csv
import functools
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import delete
from typer.testing import CliRunner

import test_study_support
from cfteach.study.bot import run_participant
from cfteach.study.build import init_study, toy_sources
from cfteach.study.config import StudyError, load_study
from cfteach.study.export import export_csv
from cfteach.study.models import StudyVersion
from cfteach.study.server import create_app
from test_study_support import researcher_progress, session_state

db_url = test_study_support.db_url  # shared fixture

PARAMS = {"prolific_pid": "5f1c0ffee0ddba11c0ffee00", "study_id": "S1", "session_id": "X1"}


@functools.cache
def _toy() -> list:
    return toy_sources()


def _read(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))




def _init(folder: Path, title: str, code: str) -> str:
    init_study(folder, _toy(), title=title, completion_code=code, demo_step_ms=10)
    return load_study(folder)["version"]


def test_a_changed_study_file_keeps_serving_sessions_started_on_the_old_one(
        tmp_path: Path, db_url: str) -> None:
    folder = tmp_path / "study"
    v1 = _init(folder, "First study", "CODE1")
    app = create_app(folder, db_url, seed=1)
    with TestClient(app) as c:
        mid = run_participant(c, PARAMS, stop_after=8)
    app.state.service.engine.dispose()
    v2 = _init(folder, "Second study", "CODE2")
    assert v1 != v2
    app = create_app(folder, db_url, researcher_token="rt", seed=2)
    with TestClient(app) as c:
        assert "Second study" in c.get("/").text
        back = c.post("/api/session", json=PARAMS).json()
        assert back["token"] == mid["token"] and back["resumed"] is True
        st = session_state(c, back["token"])
        assert st["step_index"] == 8 and st["step"]["kind"] == "test"
        # shown, not counted in cells
        assert researcher_progress(c)["older_versions_in_progress"] == 1
        assert "in progress on older study versions: 1" in c.get("/researcher?token=rt").text
        done = run_participant(c, PARAMS)  # resumes by PID and finishes on version 1
        assert done["state"]["step"]["code"] == "CODE1"
        assert done["state"]["step"]["redirect"].endswith("cc=CODE1")
        new = run_participant(c, {**PARAMS, "prolific_pid": "newcomer01"})
        assert new["state"]["step"]["code"] == "CODE2"
        prog = researcher_progress(c)
        assert prog["study_version"] == v2 and prog["status"] == {"completed": 1}
        assert prog["older_versions_in_progress"] == 0
    app.state.service.engine.dispose()
    export_csv(db_url, tmp_path / "out")
    versions = {r["prolific_pid"]: (r["status"], r["study_version"])
                for r in _read(tmp_path / "out" / "participants.csv")}
    assert versions == {PARAMS["prolific_pid"]: ("completed", v1),
                        "newcomer01": ("completed", v2)}


def test_sessions_on_an_unstored_study_file_block_a_restart_unless_new_version(
        tmp_path: Path, db_url: str) -> None:
    from cfteach.cli import app as cli

    folder = tmp_path / "study"
    _init(folder, "First study", "CODE1")
    app = create_app(folder, db_url, seed=1)
    with TestClient(app) as c:
        mid = run_participant(c, PARAMS, stop_after=3)
    svc = app.state.service
    with svc.Session() as db, db.begin():  # a database from before study files were kept
        db.execute(delete(StudyVersion))
    svc.engine.dispose()
    # The unchanged file still starts (and is stored again).
    create_app(folder, db_url).state.service.engine.dispose()
    with svc.Session() as db, db.begin():
        db.execute(delete(StudyVersion))
    svc.engine.dispose()
    _init(folder, "Second study", "CODE2")
    with pytest.raises(StudyError, match="1 session.* in progress .*--new-version"):
        create_app(folder, db_url)
    from cfteach.study.livesrv import free_port

    r = CliRunner().invoke(cli, ["serve", "--study", str(folder), "--db", db_url,
                                 "--port", str(free_port())])  # serve checks its port first
    assert r.exit_code == 1 and "--new-version" in r.output
    assert "Traceback" not in r.output and len(r.output.strip().splitlines()) == 1
    app = create_app(folder, db_url, new_version=True)
    with TestClient(app) as c:
        r = c.get("/api/state", headers={"X-Session-Token": mid["token"]})
        assert r.status_code == 410 and r.json()["error"] == "study_changed"
        assert run_participant(c, {**PARAMS, "prolific_pid": "newcomer02"})[
            "state"]["step"]["code"] == "CODE2"
    app.state.service.engine.dispose()
