"""The participant page in Chromium: a demonstration starts only once its start is stored,
a network fault never blames the participant, the "preparing the next item" state, the
demonstration banner fits its board, and a one-game study is told about one game."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from sqlalchemy import select

import test_study_browser
from cfteach.study.build import init_study, toy_sources
from cfteach.study.config import load_study
from cfteach.study.livesrv import running
from cfteach.study.models import Event
from cfteach.study.server import create_app
from test_study_a11y_browser import axe_problems
from test_study_browser import Participant, _run
from test_study_browser_network import Faults

pytestmark = [pytest.mark.browser, pytest.mark.slow]
browser = test_study_browser.browser
API = re.compile(r"^http://127\.0\.0\.1:\d+/api/")


@pytest.fixture(scope="module")
def slow_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """100 ms per demonstration step: a toy replay (9 to 13 steps) must be watched for
    at least 650 ms on the server's clock to count."""
    out = tmp_path_factory.mktemp("slow_study")
    init_study(out, toy_sources(), demo_step_ms=100, completion_code="C0MPL3TE")
    return out


def _open(browser, study: Path, tmp_path: Path, pid: str):  # noqa: ANN001, ANN202
    app = create_app(study, f"sqlite:///{tmp_path / f'{pid}.db'}", seed=4)
    return app


def test_a_play_starts_once_its_start_is_stored(browser, slow_study: Path,  # noqa: ANN001
                                                tmp_path: Path) -> None:
    """A 429 on the play's start event (Retry-After: 1) holds the replay back instead of
    letting the server time a full play as a 10 ms one; the participant then continues."""
    app = _open(browser, slow_study, tmp_path, "held")
    with running(app) as base:
        ctx = browser.new_context(viewport={"width": 1000, "height": 700})
        page = ctx.new_page()
        faults = Faults(page)
        page.goto(f"{base}/?PROLIFIC_PID=heldplay01&STUDY_ID=st1&SESSION_ID=se1")
        who = Participant(page, base, load_study(slow_study))
        who.run(stop_at="demos")
        faults.arm("429")
        page.click("#play")
        page.wait_for_timeout(500)  # five replay steps' worth
        assert page.get_attribute("#board", "data-frame") == "0"  # not started yet
        assert page.get_attribute("#play", "data-state") == "starting"
        page.wait_for_selector("#play[data-state='done']", timeout=15_000)
        assert faults.served == [("429", "demo_play_start")]
        page.click("#next")
        page.wait_for_selector("#board[data-demo='1']")
        page.click("#play")
        page.wait_for_selector("#play[data-state='done']", timeout=15_000)
        idx = page.get_attribute("main", "data-step-index")
        page.click("#next:not([disabled])")
        who.wait_next_step(idx)
        assert who.step() == "survey"
        assert page.query_selector("#error") is None
        with app.state.service.Session() as db:
            ends = db.scalars(select(Event).where(Event.type == "demo_play_end")).all()
        assert [e.verified for e in ends] == [True, True]
        assert min(e.server_ms for e in ends) >= 650
        ctx.close()
    app.state.service.engine.dispose()


def test_a_refused_play_never_blames_the_participant(browser, tmp_path: Path) -> None:  # noqa: ANN001
    """The server refuses `continue` with demos_unwatched although every demonstration has
    played to its end on the page (its end events were lost, say): the page must not tell
    the participant to watch every demonstration."""
    study = tmp_path / "toy"
    init_study(study, toy_sources(), demo_step_ms=15, completion_code="C0MPL3TE")
    app = _open(browser, study, tmp_path, "blame")
    with running(app) as base:
        ctx = browser.new_context(viewport={"width": 1000, "height": 700})
        page = ctx.new_page()
        page.goto(f"{base}/?PROLIFIC_PID=noblame01&STUDY_ID=st1&SESSION_ID=se1")
        who = Participant(page, base, load_study(study))
        who.run(stop_at="demos")
        for k in (0, 1):
            page.wait_for_selector(f"#board[data-demo='{k}']")
            page.click("#play")
            page.wait_for_selector("#next:not([disabled])")
            if k == 0:
                page.click("#next")
        refused: list[str] = []

        def refuse(route) -> None:  # noqa: ANN001
            body = json.loads(route.request.post_data or "{}")
            if route.request.url.endswith("/api/event") and body.get("type") == "continue" \
                    and not refused:
                refused.append(body["type"])
                route.fulfill(status=409, json={"error": "demos_unwatched",
                                                "detail": "the demonstrations must be watched"})
                return
            route.continue_()

        page.route(API, refuse)
        page.click("#next")
        page.wait_for_selector("#error")
        msg = page.text_content("#error")
        assert refused == ["continue"]
        assert "Please watch every demonstration" not in msg, msg
        assert "connection" in msg, msg
        ctx.close()
    app.state.service.engine.dispose()


def test_the_page_waits_while_the_next_item_is_prepared(browser, tmp_path: Path) -> None:  # noqa: ANN001
    """An event answered 202 (stored, the next page not ready) and states that say
    `preparing`: the page shows "Preparing the next item" and asks again until it is
    ready, storing the event once."""
    study = tmp_path / "toy"
    init_study(study, toy_sources(), demo_step_ms=15, completion_code="C0MPL3TE")
    app = _open(browser, study, tmp_path, "prep")
    with running(app) as base:
        ctx = browser.new_context(viewport={"width": 1000, "height": 700})
        page = ctx.new_page()
        page.goto(f"{base}/?PROLIFIC_PID=preparing01&STUDY_ID=st1&SESSION_ID=se1")
        who = Participant(page, base, load_study(study))
        who.run(stop_at="instructions")
        plan = {"accepted": 1, "preparing": 4}
        polls: list[int] = []

        def slow_teacher(route) -> None:  # noqa: ANN001
            req = route.request
            if req.url.endswith("/api/event") and plan["accepted"]:
                plan["accepted"] -= 1
                route.fetch()  # stored by the server; the answer says: not ready yet
                route.fulfill(status=202, json={"ok": True, "preparing": True})
                return
            if req.url.endswith("/api/state") and req.method == "GET":
                res = route.fetch()
                polls.append(res.status)
                data = res.json()
                if plan["preparing"]:
                    plan["preparing"] -= 1
                    data["preparing"] = True
                route.fulfill(status=200, json=data)
                return
            route.continue_()

        page.route(API, slow_teacher)
        page.click("#next")
        page.wait_for_selector("main[data-step='preparing'] #preparing")
        assert "Preparing the next item" in page.text_content("main h1")
        assert axe_problems(page) == []
        page.wait_for_selector("main[data-step='free_play']", timeout=15_000)
        assert len(polls) == 5 and plan == {"accepted": 0, "preparing": 0}
        assert page.query_selector("#error") is None
        with app.state.service.Session() as db:
            n = db.scalars(select(Event).where(Event.type == "continue")).all()
        assert len(n) == 1
        ctx.close()
    app.state.service.engine.dispose()


class OneGameParticipant(Participant):
    """Keeps each page's text; checks that the demonstration banner fits its board."""

    def before_step(self, kind: str) -> None:
        self.texts = getattr(self, "texts", {})
        if kind != "complete":  # leaves for Prolific after 1.5 s
            self.texts.setdefault(kind, self.page.text_content("main"))

    def _demos(self) -> None:
        page = self.page
        page.wait_for_selector("#board[data-demo='0']")
        page.click("#play")
        page.wait_for_selector("#board [data-kind='banner']")
        box = page.eval_on_selector("#board svg", """svg => {
          const t = svg.querySelector("[data-kind='banner']").getBBox();
          return {x: t.x, w: t.width, width: svg.viewBox.baseVal.width}; }""")
        self.banner = box
        page.reload()
        super()._demos()


def test_a_one_game_study_is_told_about_one_game(browser, tmp_path: Path) -> None:  # noqa: ANN001
    study = tmp_path / "one"
    init_study(study, toy_sources(("toy_a",)), demo_step_ms=15, completion_code="C0MPL3TE")
    who, _out, _db = _run(browser, study, tmp_path, make=OneGameParticipant)
    every = " ".join(who.texts.values())
    assert not re.search(r"\bthree\b|main games|next one|null", every), every
    assert "playing a simple game" in who.texts["consent"]
    assert "the game of this study" in who.texts["instructions"]
    assert "the main game and begin" in who.texts["post_practice"]
    assert "getting through the main game!" in who.texts["demographics"]
    assert "play six games" in who.texts["test"]
    # "Demonstration complete" fits the 4-cell-wide toy board (it was cut at both ends)
    b = who.banner
    assert b["x"] >= 0 and b["x"] + b["w"] <= b["width"], b
