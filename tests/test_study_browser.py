"""End-to-end: Debian's headless Chromium plays the whole study through the real page.

A participant consents, practises, watches every demonstration, answers the surveys and
plays every test with key presses; the export must then hold exactly their answers, scored
right (checked against an independent replay with the domain's own `step`). A second run
reloads the page mid-study and must lose and duplicate nothing.
"""

from __future__ import annotations

import csv
import functools
import json
import math
from pathlib import Path

import httpx
import pytest
from sqlalchemy import func, select

import test_study_support
from cfteach.study.build import init_study, preview_sources, teaching_sources, toy_sources
from cfteach.study.config import load_study
from cfteach.study.db import make_engine
from cfteach.study.export import export_csv
from cfteach.study.games import best_path, shortest_path
from cfteach.study.livesrv import running
from cfteach.study.models import Event, TestResponse
from cfteach.study.screenshots import ARGS, CHROMIUM, KEYS
from cfteach.study.server import create_app

pytestmark = [pytest.mark.browser, pytest.mark.slow]
toy_study = test_study_support.toy_study

PID = "60aa0bb0cc0dd0ee0ff00112"


@pytest.fixture(scope="module")
def browser():  # noqa: ANN201
    playwright = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: install Debian's chromium (scripts/setup --system)")
    with playwright.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        yield b
        b.close()


@functools.cache
def _sources(kind: str) -> dict:
    if kind == "paper":
        made = teaching_sources()  # the real teaching: cfteach.teaching.teach/select_tests
    else:
        made = toy_sources() if kind == "toy" else preview_sources(seed=0)
    return {s.domain.name: s for s in made}


def _independent(kind: str, test_id: str, actions: list[str]) -> tuple[float, float]:
    """Replay with the domain's own `step` (not the server's table): reward, optimum."""
    dom, level, i = test_id.rsplit("-", 2)
    src = _sources(kind)[dom]
    t = src.tests["tests"][level][int(i)]
    inst = src.domain.instances()[t["env_index"]]
    s, mu = inst.state_from_json(t["start_state"]), [0.0, 0.0, 0.0]
    for a in actions:
        s, phi, _ = inst.step(s, list(src.domain.actions).index(a))
        mu = [m + float(f) for m, f in zip(mu, phi, strict=True)]
    reward = sum(float(w) * m for w, m in zip(src.domain.weights, mu, strict=True))
    return reward, t["optimal_reward"]


class Participant:
    """Drives the page like a person would; remembers what it answered."""

    def __init__(self, page, base: str, study: dict) -> None:  # noqa: ANN001
        self.page, self.base, self.study = page, base, study
        self.played: dict[tuple[str, int], list[str]] = {}
        self.confidence: dict[tuple[str, int], int] = {}
        self.likert: dict[str, tuple[int, int]] = {}
        self.feedback: dict[str, str] = {}

    def state(self) -> dict:
        token = self.page.evaluate("sessionStorage.getItem('cfteach-token')")
        return httpx.get(f"{self.base}/api/state", headers={"X-Session-Token": token}).json()

    def step(self) -> str:
        """The page on screen, once it is one to act on: the "preparing the next item" page
        (a closed-loop item still being decided, e.g. on a busy machine) passes by itself.
        The first decision of a server also builds its decision workers' lesson pool, which
        takes seconds, and more while other test workers share the cores: a stuck page still
        fails, after two minutes rather than thirty seconds."""
        self.page.wait_for_selector("main[data-step]:not([data-step='preparing'])",
                                    timeout=120_000)
        return self.page.get_attribute("main", "data-step")

    def wait_next_step(self, old_index: str) -> None:
        self.page.wait_for_selector(f"main[data-step]:not([data-step-index='{old_index}'])")

    def click_next(self) -> None:
        idx = self.page.get_attribute("main", "data-step-index")
        self.page.click("#next:not([disabled])")
        self.wait_next_step(idx)

    def press(self, moves: list[str]) -> None:
        for m in moves:
            self.page.keyboard.press(KEYS[m])

    def before_step(self, kind: str) -> None:
        """Called once per page, before it is acted on (subclasses inject faults here)."""

    def run(self, *, reload_on: set[str] = frozenset(), stop_at: str | None = None) -> None:
        page = self.page
        reloaded: set[str] = set()
        seen: set[str] = set()
        while True:
            kind = self.step()
            if kind == stop_at:
                return
            index = page.get_attribute("main", "data-step-index")
            if index not in seen and kind not in reload_on - reloaded:
                seen.add(index)
                self.before_step(kind)
            if kind in reload_on and kind not in reloaded:
                reloaded.add(kind)
                self._reload_mid(kind)
                continue
            if kind == "consent":
                assert page.is_disabled("#agree")
                for k in ("adult", "read", "agree"):
                    page.check(f"#c-{k}")
                idx = page.get_attribute("main", "data-step-index")
                page.click("#agree")
                self.wait_next_step(idx)
            elif kind in ("instructions", "post_practice", "domain_intro"):
                self.click_next()
            elif kind == "free_play":
                page.click("#board")
                self.press(["right", "up", "pickup"])
                page.keyboard.press("r")
                assert page.get_attribute("#board", "data-moves") == ""
                self.click_next()
            elif kind == "practice":
                st = self.state()["step"]
                page.click("#board")
                self.press(best_path(st["game"], st["weights"]))
                page.wait_for_selector("#practice-msg:has-text('Good job')")
                self.click_next()
            elif kind == "demos":
                self._demos()
            elif kind == "survey":
                dom = self.state()["step"]["domain"]
                inf, eff = 4, 2 if dom.endswith("a") else 5
                page.check(f"input[name=informativeness][value='{inf}']")
                page.check(f"input[name=mental_effort][value='{eff}']")
                self.likert[dom] = (inf, eff)
                self.click_next()
            elif kind == "test":
                self._test()
            elif kind == "feedback":
                st = self.state()["step"]
                self.feedback[st["domain"]] = page.text_content("#score")
                self.click_next()
            elif kind == "demographics":
                page.fill("input[name=age]", "34")
                page.check("input[name=gender][value='Non-binary']")
                page.select_option("select[name=education]", "Master's degree")
                self.click_next()
            elif kind in ("complete", "screened_out"):
                return
            else:  # pragma: no cover
                raise AssertionError(f"unexpected page {kind}")

    def _demos(self) -> None:
        page = self.page
        n = len(self.state()["step"]["demos"])
        page.wait_for_selector("#board[data-demo]")
        start = int(page.get_attribute("#board", "data-demo"))  # after a reload: first unwatched
        for k in range(start, n):
            page.wait_for_selector(f"#board[data-demo='{k}']")
            page.click("#play")
            page.wait_for_selector("#next:not([disabled])")
            if k == 1:  # rewatch the first one, as people do
                page.click("#prev")
                page.wait_for_selector("#board[data-demo='0']")
                page.click("#play")
                page.wait_for_selector("#play:not([disabled])")
                page.click("#next")
                page.wait_for_selector("#board[data-demo='1']")
            if k < n - 1:
                page.click("#next")
        self.click_next()

    def _test(self) -> None:
        page = self.page
        st = self.state()["step"]
        key = (st["domain"], st["trial"])
        dom_study = self.study["tests"][st["domain"]]
        test = next(t for ts in dom_study for t in ts if t["game"]["states"] ==
                    st["game"]["states"] and t["layout"] == st["layout"])
        weights = self.study["domain_info"][st["domain"]]["weights"]
        moves = best_path(test["game"], weights) if st["trial"] % 2 else shortest_path(st["game"])
        assert page.is_disabled("#next")
        conf = 1 + (st["trial"] % 5)
        how = st["trial"] % 3
        if how == 1:
            page.click("#board")
        elif how == 2:  # answer first: the radio button keeps the focus, yet keys play the game
            page.click(f"input[name=confidence][value='{conf}']")
            assert page.evaluate("document.activeElement.name") == "confidence"
        # else: no click at all, right after the last game's Submit
        before = page.evaluate("window.scrollY")
        self.press(moves)
        assert page.evaluate("window.scrollY") == before  # arrow keys never scroll
        page.wait_for_selector("#board[data-ended='true']")
        assert page.get_attribute("#board", "data-moves") == " ".join(moves)
        if how == 2:
            assert page.evaluate("document.activeElement.name") == "confidence"
            assert page.is_checked(f"input[name=confidence][value='{conf}']")
        page.check(f"input[name=confidence][value='{conf}']")
        self.played[key] = moves
        self.confidence[key] = conf
        self.click_next()

    def _reload_mid(self, kind: str) -> None:
        page = self.page
        before = self.state()
        if kind == "test":
            page.click("#board")
            self.press(["up", "left"])  # a few moves, then the page is reloaded
            page.wait_for_timeout(2500)
        elif kind == "demos":
            page.click("#play")
            page.wait_for_selector("#next:not([disabled])")
        page.reload()
        page.wait_for_selector(f"main[data-step='{kind}']")
        after = self.state()
        assert after["step_index"] == before["step_index"]
        if kind == "test":
            assert page.get_attribute("#board", "data-moves") == ""  # the game restarts
            assert after["step"]["trial"] == before["step"]["trial"]
        if kind == "demos":
            assert after["step"]["completed"][0] == 1  # the finished viewing was kept


def _rows(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _run(browser, toy_study: Path, tmp_path: Path, *, make=Participant,  # noqa: ANN001
         prepare=None, **kw) -> tuple[Participant, Path, str]:  # noqa: ANN001
    """One participant through the whole study; `prepare(page)` runs before the first load."""
    db = f"sqlite:///{tmp_path / 'e2e.db'}"
    app = create_app(toy_study, db, researcher_token="tok", seed=11)
    study = load_study(toy_study)
    with running(app) as base:
        ctx = browser.new_context(viewport={"width": 1000, "height": 500})
        page = ctx.new_page()
        if prepare is not None:
            prepare(page)
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        redirected: list[str] = []
        page.route("https://app.prolific.com/**", lambda route: (
            redirected.append(route.request.url),
            route.fulfill(status=200, body="<p>prolific</p>", content_type="text/html")))
        page.goto(f"{base}/?PROLIFIC_PID={PID}&STUDY_ID=st1&SESSION_ID=se1")
        who = make(page, base, study)
        who.run(**kw)
        assert page.text_content("#code") == "C0MPL3TE"
        page.wait_for_url("https://app.prolific.com/**", timeout=10_000)
        assert redirected == ["https://app.prolific.com/submissions/complete?cc=C0MPL3TE"]
        assert errors == []
        ctx.close()
    out = tmp_path / "export"
    export_csv(db, out)
    app.state.service.engine.dispose()
    return who, out, db


def _check_export(who: Participant, out: Path, kind: str = "toy",
                  demos: int | dict[str, int] = 2) -> None:
    (p,) = _rows(out / "participants.csv")
    assert p["prolific_pid"] == PID and p["status"] == "completed"
    assert (p["age"], p["gender"], p["education"]) == ("34", "Non-binary", "Master's degree")
    tests = _rows(out / "test_responses.csv")
    assert len(tests) == 18 == len(who.played)
    assert len({t["test_id"] for t in tests}) == 18
    correct: dict[str, int] = {}
    for t in tests:
        key = (t["domain"], int(t["trial_index"]))
        assert t["actions"].split() == who.played[key]
        assert int(t["confidence"]) == who.confidence[key]
        reward, opt = _independent(kind, t["test_id"], who.played[key])
        assert math.isclose(float(t["reward"]), reward, abs_tol=1e-9)
        assert t["optimal"] == str(int(math.isclose(reward, opt, abs_tol=1e-9)))
        if key[1] % 2:
            assert t["optimal"] == "1"  # played the best path
        assert int(t["time_ms"]) > 0
        correct[t["domain"]] = correct.get(t["domain"], 0) + int(t["optimal"])
    for dom, text in who.feedback.items():  # the score page showed the server's score
        assert f"you got {correct[dom]} out of 6" in text
    likert = _rows(out / "likert.csv")
    assert len(likert) == 6
    for r in likert:
        inf, eff = who.likert[r["domain"]]
        assert int(r["value"]) == (inf if r["item"] == "informativeness" else eff)
    views = _rows(out / "demo_views.csv")
    assert len(views) == (3 * demos if isinstance(demos, int) else sum(demos.values()))
    for v in views:  # the first demonstration of each domain was watched twice
        expected = ("2", "1") if v["demo_index"] == "0" else ("1", "0")
        assert (v["plays_completed"], v["replays"]) == expected
        assert int(v["watch_ms"]) > 0


def test_browser_full_study(browser, toy_study: Path, tmp_path: Path) -> None:  # noqa: ANN001
    who, out, _ = _run(browser, toy_study, tmp_path)
    _check_export(who, out)


def test_browser_reload_mid_study_resumes(browser, toy_study: Path,  # noqa: ANN001
                                          tmp_path: Path) -> None:
    who, out, db = _run(browser, toy_study, tmp_path, reload_on={"demos", "test", "survey"})
    _check_export(who, out)
    engine = make_engine(db)
    with engine.connect() as conn:
        n, lo, hi = conn.execute(select(func.count(), func.min(Event.seq),
                                        func.max(Event.seq))).one()
        loads = conn.execute(select(func.count()).where(Event.type == "page_load")).scalar()
        times = conn.execute(select(TestResponse.time_ms, TestResponse.server_ms)).all()
    engine.dispose()
    # time_ms runs from the test's first showing, across the reload (2.5 s spent before it).
    assert len(times) == 18
    assert all(abs(t - s) < 1500 for t, s in times), times
    assert (lo, hi) == (1, n)  # gap-free, in order
    assert loads == 3  # one per reload


def test_browser_full_study_on_the_real_domains(browser, tmp_path: Path) -> None:  # noqa: ANN001
    """Delivery, tiles and skateboard as drawn and played in the page (placeholder curricula:
    optimal demonstrations from random instances)."""
    study = tmp_path / "real"
    init_study(study, preview_sources(seed=0), demo_step_ms=15, completion_code="C0MPL3TE")
    who, out, _ = _run(browser, study, tmp_path)
    _check_export(who, out, kind="preview", demos=3)


def test_browser_events_made_offline_are_sent_after_reload(browser, toy_study: Path,  # noqa: ANN001
                                                           tmp_path: Path) -> None:
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'off.db'}", seed=5)
    with running(app) as base:
        ctx = browser.new_context(viewport={"width": 1000, "height": 700})
        page = ctx.new_page()
        page.goto(f"{base}/?PROLIFIC_PID=offline01&STUDY_ID=st1&SESSION_ID=se1")
        who = Participant(page, base, load_study(toy_study))
        who.run(stop_at="demos")
        assert who.state()["step"]["completed"][0] == 0
        ctx.set_offline(True)
        page.click("#play")  # the play's start cannot reach the server: the replay waits
        page.wait_for_selector("#net-status", state="visible")
        page.wait_for_timeout(300)
        assert page.get_attribute("#play", "data-state") == "starting"
        assert page.get_attribute("#board", "data-frame") == "0"
        token = page.evaluate("sessionStorage.getItem('cfteach-token')")
        pending = json.loads(page.evaluate(f"localStorage.getItem('cfteach-pending-{token}')"))
        assert [e["type"] for e in pending] == ["demo_play_start"]
        ctx.set_offline(False)
        page.reload()  # the stored start is sent before the page is drawn
        page.wait_for_selector("main[data-step='demos']")
        assert page.evaluate(f"localStorage.getItem('cfteach-pending-{token}')") == "[]"
        assert who.state()["step"]["completed"][0] == 0  # a start alone is no viewing
        page.click("#play")  # online again: the replay plays and counts
        page.wait_for_selector("#play[data-state='done']")
        assert who.state()["step"]["completed"][0] == 1
        assert page.is_enabled("#next")
        ctx.close()
    app.state.service.engine.dispose()


def test_browser_practice_lockout_after_three_failures(browser, toy_study: Path,  # noqa: ANN001
                                                       tmp_path: Path) -> None:
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'lock.db'}", seed=6)
    with running(app) as base:
        ctx = browser.new_context(viewport={"width": 1000, "height": 700})
        page = ctx.new_page()
        redirected: list[str] = []
        page.route("https://app.prolific.com/**", lambda route: (
            redirected.append(route.request.url),
            route.fulfill(status=200, body="<p>prolific</p>", content_type="text/html")))
        page.goto(f"{base}/?PROLIFIC_PID=lockout01&STUDY_ID=st1&SESSION_ID=se1")
        who = Participant(page, base, load_study(toy_study))
        who.run(stop_at="practice")
        st = who.state()["step"]
        # A wasted step out and back, then the best route: 10% short of the target (twice);
        # then steps to and fro until the energy is gone.
        wasteful = ["down", "up", *best_path(st["game"], st["weights"])]
        page.click("#board")
        for attempt in range(3):
            if attempt:
                page.keyboard.press("r")
                page.wait_for_selector("#board[data-moves='']")
                assert page.text_content("#practice-msg") == ""  # the last verdict is gone
            who.press(wasteful if attempt < 2 else ["down", "up"] * 10)
            if attempt < 2:
                page.wait_for_selector(f"#energy:has-text('Attempts remaining: {2 - attempt}')")
            else:
                page.wait_for_selector("#practice-msg:has-text(\"don't qualify\")")
            # What was reached and what was needed, in the message and on the board (which
            # no longer says "Game completed!" next to a failure).
            msg = page.text_content("#practice-msg")
            banner = page.text_content("#board [data-kind='banner']")
            if attempt < 2:
                assert "with 40% energy left" in msg and "finish with 50%" in msg, msg
                assert banner == "Not enough energy40% left, 50% needed", banner
            else:
                assert "ran out of energy (0% left)" in msg and "with 50% energy" in msg, msg
                assert banner == "Out of energy0% left, 50% needed", banner
            assert "fail" in page.get_attribute("#board [data-kind='banner']", "class")
        page.reload()  # a reload cannot bring the practice back
        page.wait_for_selector("main[data-step='screened_out']")
        assert page.text_content("#code") == "SCR33N"
        page.wait_for_url("https://app.prolific.com/**", timeout=10_000)
        assert redirected == ["https://app.prolific.com/submissions/complete?cc=SCR33N"]
        ctx.close()
    app.state.service.engine.dispose()


def test_browser_full_study_on_the_paper_default_study(browser, tmp_path: Path) -> None:  # noqa: ANN001
    """The default study (`cfteach study init` without --from): curricula and tests made by
    cfteach.teaching for the three domains, played through in Chromium."""
    study = tmp_path / "paper"
    init_study(study, _sources("paper").values(), demo_step_ms=10, completion_code="C0MPL3TE")
    who, out, _ = _run(browser, study, tmp_path)
    (p,) = _rows(out / "participants.csv")
    demos = {d: len(_sources("paper")[d].curricula[p["condition"]]["demos"])
             for d in ("delivery", "tiles", "skateboard")}
    _check_export(who, out, kind="paper", demos=demos)


def test_browser_shows_the_researchers_consent_text(browser, tmp_path: Path) -> None:  # noqa: ANN001
    study = tmp_path / "consent"
    init_study(study, toy_sources(), consent_html="<h2>Procedures</h2><p id='irb'>IRB "
               "protocol 2026-042: you will play short games.</p>")
    app = create_app(study, f"sqlite:///{tmp_path / 'c.db'}")
    with running(app) as base:
        page = browser.new_page()
        page.goto(f"{base}/?PROLIFIC_PID=consent01")
        page.wait_for_selector("#consent-text #irb")
        assert "IRB protocol 2026-042" in page.text_content("#consent-text")
        assert page.is_disabled("#agree")
        page.close()
    app.state.service.engine.dispose()
