"""Chromium against a flaky network: failed requests are retried, refused ones reported.

A route in front of the page fails the next API request on every kind of page, once with a
proxy's 502 (after the server has done the work, so only its answer is lost) and once with
a 429 carrying Retry-After; the participant must still get through the whole study with
every answer stored exactly once. A request the server refuses for good must end as a
report the researcher can read, with a plain message to the participant instead of the
server's raw text.
"""

from __future__ import annotations

import json
import re
import time
from collections import Counter
from itertools import pairwise
from pathlib import Path

import pytest
from sqlalchemy import func, select

import test_study_browser
import test_study_support
from cfteach.study.config import load_study
from cfteach.study.db import make_engine
from cfteach.study.export import export_csv
from cfteach.study.games import best_path
from cfteach.study.livesrv import running
from cfteach.study.models import ClientReport, Event
from cfteach.study.models import TestResponse as Answer
from cfteach.study.server import create_app
from test_study_browser import Participant, _check_export, _rows, _run

pytestmark = [pytest.mark.browser, pytest.mark.slow]
toy_study = test_study_support.toy_study
browser = test_study_browser.browser

API = re.compile(r"^http://127\.0\.0\.1:\d+/api/")
PROXY_PAGE = "<html><body><h1>502 Bad Gateway</h1><hr>nginx</body></html>"
COUNT_STATUS_LINE = """document.addEventListener("DOMContentLoaded", () => {
  const box = document.getElementById("net-status");
  if (!box) return;  // Prolific's page, after the redirect
  window.netStatusShown = 0;
  new MutationObserver(() => { if (!box.hidden) window.netStatusShown += 1; })
    .observe(box, { attributes: true });
});"""


class Faults:
    """Fails the next API requests as planned: `502-lost` lets the request reach the server
    and loses its answer; `502`, `429` (Retry-After: 1) and `429-bare` (no Retry-After) stop
    it before the server. `seen` logs every API request: (time, fault or None)."""

    def __init__(self, page) -> None:  # noqa: ANN001
        self.plan: list[str] = []
        self.served: list[tuple[str, str]] = []
        self.seen: list[tuple[float, str | None]] = []
        page.route(API, self._handle)

    def arm(self, *faults: str) -> None:
        self.plan.extend(faults)

    def _handle(self, route) -> None:  # noqa: ANN001
        fault = self.plan.pop(0) if self.plan else None
        self.seen.append((time.monotonic(), fault))
        if fault is None:
            route.continue_()
            return
        req = route.request
        what = req.url.split("/api/")[1]
        if what == "event":
            what = json.loads(req.post_data)["type"]
        self.served.append((fault, what))
        if fault.startswith("429"):
            route.fulfill(status=429, headers={} if fault == "429-bare" else {
                "Retry-After": "1"}, json={"error": "rate_limited", "detail": "slow down"})
            return
        if fault == "502-lost":
            route.fetch()  # the server stores the event; the proxy loses the answer
        route.fulfill(status=502, body=PROXY_PAGE, content_type="text/html")


class FlakyParticipant(Participant):
    """On every page, the next API request fails twice before it gets through."""

    faults: Faults

    def before_step(self, kind: str) -> None:
        if kind in ("complete", "screened_out"):
            return
        self.kinds_seen[kind] += 1
        # First page of a kind: a lost answer, then rate limited (Retry-After: 1); the second
        # page of a kind (domain intro, demonstrations, survey, test, score): rate limited
        # without Retry-After, then a request lost on its way.
        if self.kinds_seen[kind] <= 2:
            self.faults.arm(*(("502-lost", "429") if self.kinds_seen[kind] == 1
                              else ("429-bare", "502")))
            self.armed_on.append(kind)

    def run(self, **kw) -> None:  # noqa: ANN003
        self.kinds_seen: Counter[str] = Counter()
        self.armed_on: list[str] = []
        super().run(**kw)
        self.page.wait_for_selector("#net-status", state="hidden")
        # The "connection interrupted" line came up for every failed step (and went away).
        assert self.page.evaluate("window.netStatusShown") >= len(self.armed_on)
        token = self.page.evaluate("sessionStorage.getItem('cfteach-token')")
        left = self.page.evaluate(f"localStorage.getItem('cfteach-pending-{token}')")
        assert json.loads(left) == []  # nothing waits in the browser any more
        assert self.page.query_selector("#error") is None


def test_every_kind_of_page_survives_a_502_and_a_429(browser, toy_study: Path,  # noqa: ANN001
                                                      tmp_path: Path) -> None:
    holder: dict[str, Faults] = {}

    def prepare(page) -> None:  # noqa: ANN001
        holder["faults"] = Faults(page)
        page.add_init_script(COUNT_STATUS_LINE)
        holder["faults"].arm("502-lost", "429")  # the session start itself

    def make(page, base: str, study: dict) -> FlakyParticipant:  # noqa: ANN001
        who = FlakyParticipant(page, base, study)
        who.faults = holder["faults"]
        return who

    who, out, db = _run(browser, toy_study, tmp_path, make=make, prepare=prepare)
    faults = holder["faults"]
    kinds = {"consent", "instructions", "free_play", "practice", "post_practice",
             "domain_intro", "demos", "survey", "test", "feedback", "demographics"}
    assert set(who.armed_on) == kinds and len(who.armed_on) == len(kinds) + 5
    assert faults.plan == []  # every planned failure was served ...
    assert len(faults.served) == 2 + 2 * len(who.armed_on)
    hit = {what for _, what in faults.served}  # ... to requests of every kind of step
    assert {"session", "consent", "continue", "practice_attempt", "demo_play_start",
            "likert", "test_response", "demographics"} <= hit
    assert Counter(f for f, _ in faults.served) == {"502-lost": 12, "429": 12, "429-bare": 5,
                                                    "502": 5}
    # Requests go one at a time, so the request after a 429 is its retry: never sooner than
    # the server's Retry-After asked.
    waits = [b[0] - a[0] for a, b in pairwise(faults.seen) if a[1] == "429"]
    assert len(waits) == 12 and min(waits) >= 0.95, waits
    _check_export(who, out)  # every answer exactly once, as given
    assert _rows(out / "client_reports.csv") == []  # no request was refused for good
    engine = make_engine(db)
    with engine.connect() as conn:
        types = dict(conn.execute(select(Event.type, func.count()).group_by(Event.type)).all())
        n, lo, hi = conn.execute(select(func.count(), func.min(Event.seq),
                                        func.max(Event.seq))).one()
        tests = conn.execute(select(func.count()).select_from(Answer)).scalar()
        reports = conn.execute(select(func.count()).select_from(ClientReport)).scalar()
    engine.dispose()
    assert (lo, hi) == (1, n)
    assert tests == 18 and reports == 0
    # One of each answer; 12 continues (instructions, free play, after practice, and per
    # domain intro, demonstrations, score page); 3 plays per domain (one rewatch); the lost
    # answer to the session start made the page resume its session once (page_load).
    assert types == {"consent": 1, "continue": 12, "practice_attempt": 1, "likert": 3,
                     "test_response": 18, "demographics": 1, "demo_play_start": 9,
                     "demo_play_end": 9, "page_load": 1}


def _refused_test_answer(route) -> None:  # noqa: ANN001
    """A request tampered with on the way: the server refuses it for good (422 bad_moves)."""
    body = json.loads(route.request.post_data or "{}")
    if body.get("type") != "test_response":
        route.continue_()
        return
    body["payload"]["actions"] = body["payload"]["actions"][:1]  # no longer finishes
    route.continue_(post_data=json.dumps(body))


def test_refused_requests_are_reported_and_explained_plainly(browser, toy_study: Path,  # noqa: ANN001
                                                             tmp_path: Path) -> None:
    db = f"sqlite:///{tmp_path / 'refused.db'}"
    app = create_app(toy_study, db, seed=3)
    study = load_study(toy_study)
    raw = "every demonstration must be watched to the end at least once (plays: [1, 0, 1])"
    with running(app) as base:
        ctx = browser.new_context(viewport={"width": 1000, "height": 700})
        page = ctx.new_page()
        page.goto(f"{base}/?PROLIFIC_PID=refused01&STUDY_ID=st1&SESSION_ID=se1")
        who = Participant(page, base, study)
        who.run(stop_at="demos")

        # 1. A refusal quoting raw data (as a proxy or an older server might send it).
        once = [True]

        def unwatched(route) -> None:  # noqa: ANN001
            body = route.request.post_data
            if not (once and body and json.loads(body)["type"] == "continue"):
                route.continue_()
                return
            once.clear()
            route.fulfill(status=409, json={"error": "demos_unwatched", "detail": raw})

        page.route(API, unwatched)
        n = len(who.state()["step"]["demos"])
        for k in range(n):
            page.wait_for_selector(f"#board[data-demo='{k}']")
            page.click("#play")
            page.wait_for_selector("#next:not([disabled])")
            page.click("#next")
        page.wait_for_selector("#error")
        text = page.text_content("main")
        # every demonstration played to its end on this page: the connection is blamed,
        # never the participant
        assert "could not confirm your viewing" in page.text_content("#error")
        assert "Please watch every demonstration" not in page.text_content("#error")
        assert "plays" not in text and "[" not in text and "demos_unwatched" not in text
        assert page.get_attribute("main", "data-step") == "demos"  # redrawn from the server
        page.unroute(API, unwatched)
        who.click_next()  # the demonstrations were all watched: it goes through now

        # 2. A test answer the server refuses for good: reported with what was really sent.
        who.run(stop_at="test")
        page.route(API, _refused_test_answer)
        st = who.state()["step"]
        t = next(t for ts in study["tests"][st["domain"]] for t in ts
                 if t["game"]["states"] == st["game"]["states"])
        moves = best_path(t["game"], study["domain_info"][st["domain"]]["weights"])
        page.click("#board")
        who.press(moves)
        page.check("input[name=confidence][value='4']")
        page.click("#next")
        page.wait_for_selector("#error")
        page.unroute(API, _refused_test_answer)
        assert page.text_content("#error").startswith("Sorry, your last step could not be "
                                                      "saved. The researchers have been notified")
        text = page.text_content("main")
        assert "bad_moves" not in text and "[" not in text and "finish" not in text
        assert page.get_attribute("#board", "data-moves") == ""  # the same test, afresh
        assert who.state()["step"]["trial"] == st["trial"]
        token = page.evaluate("sessionStorage.getItem('cfteach-token')")
        assert page.evaluate(f"localStorage.getItem('cfteach-pending-{token}')") == "[]"
        who.run()  # plays it again, and the rest of the study
        assert page.text_content("#code") == "C0MPL3TE"
        ctx.close()
    out = tmp_path / "export"
    export_csv(db, out)
    app.state.service.engine.dispose()
    (p,) = _rows(out / "participants.csv")
    reports = _rows(out / "client_reports.csv")
    assert [(r["error"], r["http_status"], r["event_type"]) for r in reports] == [
        ("demos_unwatched", "409", "continue"), ("bad_moves", "422", "test_response")]
    assert all(r["participant_id"] == p["participant_id"] for r in reports)
    assert reports[0]["detail"] == raw  # kept for the researcher, never shown
    sent = json.loads(reports[1]["event"])
    assert sent["payload"]["actions"] == moves  # the page's copy: the real answer
    assert sent["payload"]["confidence"] == 4
    tests = _rows(out / "test_responses.csv")
    assert len(tests) == 18 and len({t["test_id"] for t in tests}) == 18


def test_a_refused_session_start_and_an_oversized_event_are_reported(
        browser, toy_study: Path, tmp_path: Path) -> None:  # noqa: ANN001
    db = f"sqlite:///{tmp_path / 'start.db'}"
    app = create_app(toy_study, db)
    with running(app) as base:
        page = browser.new_page()
        with page.expect_response("**/api/client-report") as reported:
            page.goto(f"{base}/?PROLIFIC_PID=not%20an%20id!&STUDY_ID=st1")  # 422 bad_parameter
        assert reported.value.status == 200
        assert page.text_content("#error") == ("The study link looks incomplete. Please open "
                                               "it again from Prolific.")
        assert "PROLIFIC_PID" not in page.text_content("main")
        # An event too big for the server (413) is reported without its payload.
        stored = page.evaluate("""async () => {
            const net = await import("/static/net.js");
            const ev = {type: "likert", step_index: 7, payload: {comment: "x".repeat(70000)}};
            return net.report("/api/event", {status: 413, data: {error: "too_large"}}, ev);
        }""")
        assert stored is True
        page.close()
    out = tmp_path / "export"
    export_csv(db, out)
    app.state.service.engine.dispose()
    r, big = _rows(out / "client_reports.csv")
    assert (r["participant_id"], r["path"], r["http_status"], r["error"]) == (
        "", "/api/session", "422", "bad_parameter")
    assert "PROLIFIC_PID" in r["detail"]
    assert (big["error"], big["event_type"], big["step_index"]) == ("too_large", "likert", "7")
    assert json.loads(big["event"])["payload"]["too_large_to_report"] > 70000
