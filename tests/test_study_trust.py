"""What the server no longer takes on trust from the browser, and what it no longer loses:
demonstration plays and test times measured on the server's clock, declined consent ending
the session, free-text comments in the export. Every API test runs on SQLite and PostgreSQL."""

from __future__ import annotations

import csv
import functools
import uuid
from datetime import timedelta
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

import test_study_browser
import test_study_support
from cfteach.study.bot import run_participant
from cfteach.study.build import init_study, toy_sources
from cfteach.study.export import COLUMNS, export_csv
from cfteach.study.games import shortest_path
from cfteach.study.models import utcnow
from cfteach.study.server import create_app
from cfteach.study.steps import DEMO_TOLERANCE_MS, demo_required_ms
from test_study_support import researcher_progress, session_state

db_url = test_study_support.db_url  # shared fixtures
toy_study = test_study_support.toy_study
browser = test_study_browser.browser

PARAMS = {"prolific_pid": "5f1c0ffee0ddba11c0ffee00", "study_id": "S1", "session_id": "X1"}
CONSENT = {"adult": True, "read": True, "agree": True}


@functools.cache
def _toy() -> list:
    return toy_sources()


@pytest.fixture(scope="module")
def slow_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The toy study replayed at the default 500 ms per step (the timing check bites)."""
    out = tmp_path_factory.mktemp("slow_study")
    init_study(out, _toy(), demo_step_ms=500)
    return out


@pytest.fixture(scope="module")
def quick_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 ms per step: every toy demonstration is shorter than the tolerance, so bots and
    a frozen clock pass the demonstrations without waiting."""
    out = tmp_path_factory.mktemp("quick_study")
    init_study(out, _toy(), demo_step_ms=10, completion_code="C0MPL3TE",
               no_consent_code="N0C0NSENT")
    return out


class Clock:
    """The service's clock, moved by hand."""

    def __init__(self) -> None:
        self.now = utcnow()

    def __call__(self):  # noqa: ANN204
        return self.now

    def tick(self, ms: int) -> None:
        self.now += timedelta(milliseconds=ms)


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Clock:
    c = Clock()
    monkeypatch.setattr("cfteach.study.service.utcnow", c)
    return c


def _read(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _event(c: TestClient, token: str, step: int, type_: str, payload: dict | None = None):  # noqa: ANN202
    return c.post("/api/event", headers={"X-Session-Token": token}, json={
        "event_id": uuid.uuid4().hex, "step_index": step, "type": type_,
        "payload": payload or {}})




# -- demonstration plays, timed by the server ----------------------------------------------


def test_demo_plays_are_checked_on_the_servers_clock(slow_study: Path, db_url: str,
                                                     clock: Clock, tmp_path: Path) -> None:
    app = create_app(slow_study, db_url, seed=2)
    with TestClient(app) as c:
        out = run_participant(c, PARAMS, stop_after=6)
        tok, st = out["token"], out["state"]
        assert st["step"]["kind"] == "demos" and st["step"]["step_ms"] == 500
        i, demos = st["step_index"], st["step"]["demos"]
        assert len(demos) == 2
        need = [demo_required_ms(len(d["actions"]), 500) for d in demos]
        assert need == [len(d["actions"]) * 500 - DEMO_TOLERANCE_MS for d in demos]

        def ev(type_: str, **payload) -> int:  # noqa: ANN003
            return _event(c, tok, i, type_, payload).status_code

        # A claimed full watch without any play start: stored, not counted.
        assert ev("demo_play_end", demo_index=0, completed=True, watch_ms=0) == 200
        # Demonstrations that do not exist on this page are refused.
        for k in (2, 99):
            r = _event(c, tok, i, "demo_play_start", {"demo_index": k})
            assert r.status_code == 422 and r.json()["error"] == "unknown_demo"
            assert ev("demo_play_end", demo_index=k, completed=True, watch_ms=9999) == 422
        # Too short on the server's clock, whatever the browser claims.
        assert ev("demo_play_start", demo_index=0) == 200
        clock.tick(need[0] - 1)
        assert ev("demo_play_end", demo_index=0, completed=True, watch_ms=60_000) == 200
        # The end of another demonstration than the one started.
        assert ev("demo_play_start", demo_index=0) == 200
        clock.tick(need[1] + 1000)
        assert ev("demo_play_end", demo_index=1, completed=True, watch_ms=7000) == 200
        # Long enough, but stopped before the end.
        assert ev("demo_play_start", demo_index=1) == 200
        clock.tick(need[1] + 5)
        assert ev("demo_play_end", demo_index=1, completed=False, watch_ms=6000) == 200
        assert session_state(c, tok)["step"]["completed"] == [0, 0]
        r = _event(c, tok, i, "continue")
        assert r.status_code == 409 and r.json()["error"] == "demos_unwatched"
        assert "demonstration 1, 2" in r.json()["detail"]
        # Played start to end for the replay's length (less the tolerance): counted.
        for k in range(2):
            assert ev("demo_play_start", demo_index=k) == 200
            clock.tick(need[k])
            assert ev("demo_play_end", demo_index=k, completed=True, watch_ms=need[k] + 300) == 200
        assert session_state(c, tok)["step"]["completed"] == [1, 1]
        assert _event(c, tok, i, "continue").status_code == 200
    app.state.service.engine.dispose()
    export_csv(db_url, tmp_path)
    views = {int(v["demo_index"]): v for v in _read(tmp_path / "demo_views.csv")}
    assert sorted(views) == [0, 1]  # demo_index 99 was never stored
    got = {k: (int(v["plays_completed"]), int(v["replays"]), int(v["watch_ms"]),
               int(v["client_watch_ms"])) for k, v in views.items()}
    assert got == {
        0: (1, 2, (need[0] - 1) + need[0], 0 + 60_000 + need[0] + 300),
        1: (1, 1, (need[1] + 5) + need[1], 7000 + 6000 + need[1] + 300),
    }


# -- test times ----------------------------------------------------------------------------


def test_test_time_is_the_servers_and_the_browsers_is_kept_apart(
        quick_study: Path, db_url: str, clock: Clock, tmp_path: Path) -> None:
    from cfteach.analysis.io import load_export

    app = create_app(quick_study, db_url, seed=3)
    with TestClient(app) as c:
        out = run_participant(c, PARAMS, stop_after=8)
        st = out["state"]
        assert st["step"]["kind"] == "test"
        clock.tick(104)
        r = _event(c, out["token"], st["step_index"], "test_response",
                   {"actions": shortest_path(st["step"]["game"]), "time_ms": 0,
                    "confidence": 3})
        assert r.status_code == 200
    app.state.service.engine.dispose()
    export_csv(db_url, tmp_path)
    (row,) = _read(tmp_path / "test_responses.csv")
    assert (row["time_ms"], row["client_time_ms"]) == ("104", "0")
    ex = load_export(tmp_path)  # the analysis reads the server's time under its old name
    assert ex.tests["time_ms"].tolist() == [104] and ex.tests["client_time_ms"].tolist() == [0]


# -- declining consent ---------------------------------------------------------------------


def test_declining_consent_ends_the_session_and_frees_its_cell(
        quick_study: Path, db_url: str, tmp_path: Path) -> None:
    from cfteach.analysis.io import STATUSES, ExportError, load_export

    app = create_app(quick_study, db_url, researcher_token="rt", seed=5)
    with TestClient(app) as c:
        tok = c.post("/api/session", json=PARAMS).json()["token"]
        assert sum(cell["occupied"] for cell in researcher_progress(c)["cells"]) == 1
        r = _event(c, tok, 0, "decline")
        assert r.status_code == 200
        st = r.json()["state"]
        assert st["status"] == "declined" and st["step"]["kind"] == "declined"
        assert st["step"]["code"] == "N0C0NSENT"
        assert st["step"]["redirect"].endswith("cc=N0C0NSENT")
        prog = researcher_progress(c)
        assert sum(cell["occupied"] for cell in prog["cells"]) == 0  # freed at once
        assert prog["status"] == {"declined": 1}
        r = _event(c, tok, 0, "consent", CONSENT)
        assert r.status_code == 409 and r.json()["error"] == "session_finished"
        again = c.post("/api/session", json=PARAMS).json()
        assert again["token"] == tok and session_state(c, tok)["step"]["kind"] == "declined"
        # Declining is an answer to the consent page only.
        other = run_participant(c, {**PARAMS, "prolific_pid": "consented1"}, stop_after=1)
        r = _event(c, other["token"], 1, "decline")
        assert r.status_code == 422 and r.json()["error"] == "wrong_event_type"
    app.state.service.engine.dispose()
    export_csv(db_url, tmp_path)
    people = {p["prolific_pid"]: p for p in _read(tmp_path / "participants.csv")}
    assert people[PARAMS["prolific_pid"]]["status"] == "declined"
    assert people[PARAMS["prolific_pid"]]["completed_at"] != ""
    # nobody has answered a test yet: the analysis says so rather than analysing nothing,
    # and its loader knows the declined status
    with pytest.raises(ExportError, match="test_responses.csv has a header but no rows"):
        load_export(tmp_path)
    assert "declined" in STATUSES


def test_old_study_files_without_a_no_consent_code_get_the_default(
        tmp_path: Path, toy_study: Path) -> None:
    import json
    import shutil

    folder = tmp_path / "old"
    shutil.copytree(toy_study, folder)
    data = json.loads((folder / "study.json").read_text())
    data["completion"].pop("declined")
    (folder / "study.json").write_text(json.dumps(data))
    app = create_app(folder, f"sqlite:///{tmp_path / 'o.db'}")
    with TestClient(app) as c:
        tok = c.post("/api/session", json=PARAMS).json()["token"]
        st = _event(c, tok, 0, "decline").json()["state"]
    app.state.service.engine.dispose()
    assert st["step"]["code"] == "NOCONSENT"


# -- free-text comments --------------------------------------------------------------------


def test_free_text_comments_are_exported(quick_study: Path, db_url: str,
                                         tmp_path: Path) -> None:
    text = 'I am Ana from "Porto", mail me: ana@example.org\nthanks, \u2713'
    app = create_app(quick_study, db_url, seed=6)
    with TestClient(app) as c:
        who = run_participant(c, PARAMS, comment=text)
        run_participant(c, {**PARAMS, "prolific_pid": "quiet00001"})  # leaves them empty
    app.state.service.engine.dispose()
    counts = export_csv(db_url, tmp_path)
    assert counts["comments.csv"] == 4
    pid = who["state"]["participant_id"]
    rows = _read(tmp_path / "comments.csv")
    assert all(r["participant_id"] == pid for r in rows)
    got = sorted((r["source"], r["domain"], r["comment"]) for r in rows)
    assert got == sorted([("demographics", "", text)] + [
        ("survey", d, f"{text} {d}") for d in ("toy_a", "toy_b", "toy_c")])
    dictionary = _read(tmp_path / "data_dictionary.csv")
    (desc,) = [d["description"] for d in dictionary
               if (d["file"], d["column"]) == ("comments.csv", "comment")]
    assert "MAY IDENTIFY" in desc
    assert [c for c, _, _ in COLUMNS["comments.csv"]] == list(rows[0])


@pytest.mark.browser
@pytest.mark.slow
def test_browser_no_thanks_shows_the_no_consent_code(browser, quick_study: Path,  # noqa: ANN001
                                                     tmp_path: Path) -> None:
    from cfteach.study.livesrv import running

    app = create_app(quick_study, f"sqlite:///{tmp_path / 'd.db'}", researcher_token="rt")
    with running(app) as base:
        page = browser.new_page()
        redirected: list[str] = []
        page.route("https://app.prolific.com/**", lambda route: (
            redirected.append(route.request.url),
            route.fulfill(status=200, body="<p>prolific</p>", content_type="text/html")))
        page.goto(f"{base}/?PROLIFIC_PID=decline01&STUDY_ID=st1&SESSION_ID=se1")
        page.wait_for_selector("#decline")
        page.click("#decline")
        page.wait_for_selector("main[data-step='declined']")
        assert page.text_content("#code") == "N0C0NSENT"
        assert "return your submission on Prolific" in page.text_content("main")
        page.wait_for_url("https://app.prolific.com/**", timeout=10_000)
        assert redirected == ["https://app.prolific.com/submissions/complete?cc=N0C0NSENT"]
        page.close()
    prog = app.state.service.progress()
    assert prog["status"] == {"declined": 1}
    assert sum(c["occupied"] for c in prog["cells"]) == 0
    app.state.service.engine.dispose()
