"""Keyboard-only participants and axe-core: every page kind of the study is usable with
the keyboard alone and has no serious or critical axe-core violation.

`KeyboardParticipant` never clicks: it moves the focus with Tab, answers every Likert and
confidence item with Space and the arrow keys, presses buttons with Enter and plays the
games with their keys. The export must then hold exactly what it chose.
"""

from __future__ import annotations

import pytest
from axe_playwright_python.sync_playwright import Axe
from sqlalchemy import update

import test_study_browser
import test_study_support
from cfteach.study.games import best_path, shortest_path
from cfteach.study.livesrv import running
from cfteach.study.models import Session
from cfteach.study.server import create_app
from test_study_browser import Participant, _rows, _run

pytestmark = [pytest.mark.browser, pytest.mark.slow]
toy_study = test_study_support.toy_study
browser = test_study_browser.browser

AXE = Axe()


def axe_problems(page) -> list[str]:  # noqa: ANN001
    """Serious and critical axe-core violations of the page as it is now, one line each."""
    found = AXE.run(page).response["violations"]
    return [f"{v['id']} ({v['impact']}): {v['help']} at "
            f"{[n['target'] for n in v['nodes']][:3]}"
            for v in found if v["impact"] in ("serious", "critical")]


class KeyboardParticipant(Participant):
    """Goes through the study with the keyboard only; checks each page kind with axe."""

    def __init__(self, *a, **k) -> None:  # noqa: ANN002, ANN003
        super().__init__(*a, **k)
        self.checked: dict[str, list[str]] = {}

    def before_step(self, kind: str) -> None:
        # the completion page leaves for Prolific after 1.5 s: checked on a preview instead
        if kind not in self.checked and kind != "complete":
            self.checked[kind] = axe_problems(self.page)

    def focused(self) -> str:
        return self.page.evaluate(
            "(() => { const e = document.activeElement; return e ? (e.id || e.name || "
            "e.tagName) + '|' + (e.type || '') + '|' + (e.value || '') : ''; })()")

    def tab_to(self, test: str, limit: int = 60) -> None:
        """Press Tab until `test` (a JS expression on `e`, the focused element) holds."""
        js = f"(() => {{ const e = document.activeElement; return Boolean(e && ({test})); }})()"
        for _ in range(limit):
            if self.page.evaluate(js):
                return
            self.page.keyboard.press("Tab")
        raise AssertionError(f"Tab never reached {test} (last: {self.focused()})")

    def enter_next(self) -> None:
        idx = self.page.get_attribute("main", "data-step-index")
        self.page.wait_for_selector("#next:not([disabled])")
        self.tab_to("e.id === 'next'")
        self.page.keyboard.press("Enter")
        self.wait_next_step(idx)

    def choose(self, name: str, nth: int) -> None:
        """Answer a radio group by keyboard: Tab into it, Space, then arrows to the `nth`
        option (1-based)."""
        self.tab_to(f"e.name === '{name}'")
        self.page.keyboard.press("Space")
        for _ in range(nth - 1):
            self.page.keyboard.press("ArrowRight")
        values = self.page.eval_on_selector_all(f"input[name={name}]", "l => l.map(e => e.value)")
        checked = self.page.eval_on_selector_all(f"input[name={name}]:checked",
                                                 "l => l.map(e => e.value)")
        assert checked == [values[nth - 1]], f"{name}: {checked} ({self.focused()})"

    def run(self, **kw) -> None:  # noqa: ANN003
        page = self.page
        seen: set[str] = set()
        while True:
            kind = self.step()
            index = page.get_attribute("main", "data-step-index")
            if index not in seen:
                seen.add(index)
                self.before_step(kind)
            if kind == kw.get("stop_at"):
                return
            if kind == "consent":
                for k in ("adult", "read", "agree"):
                    self.tab_to(f"e.id === 'c-{k}'")
                    page.keyboard.press("Space")
                self.tab_to("e.id === 'agree'")
                page.keyboard.press("Enter")
                self.wait_next_step(index)
            elif kind in ("instructions", "post_practice", "domain_intro", "feedback"):
                if kind == "feedback":
                    self.feedback[self.state()["step"]["domain"]] = page.text_content("#score")
                self.enter_next()
            elif kind == "free_play":
                self.tab_to("e.id === 'board'")
                self.press(["right", "up"])
                self.enter_next()
            elif kind == "practice":
                st = self.state()["step"]
                self.tab_to("e.id === 'board'")
                self.press(best_path(st["game"], st["weights"]))
                page.wait_for_selector("#practice-msg:has-text('Good job')")
                self.enter_next()
            elif kind == "demos":
                n = len(self.state()["step"]["demos"])
                for k in range(n):
                    self._play(k)
                    if k == 1:  # rewatch the first one, as people do
                        self.tab_to("e.id === 'prev'")
                        page.keyboard.press("Enter")
                        self._play(0)
                        self.tab_to("e.id === 'next'")
                        page.keyboard.press("Enter")
                    if k < n - 1:
                        self.tab_to("e.id === 'next'")
                        page.keyboard.press("Enter")
                self.enter_next()
            elif kind == "survey":
                dom = self.state()["step"]["domain"]
                inf, eff = (5, 2) if dom.endswith("a") else (3, 4)
                self.choose("informativeness", inf)
                self.choose("mental_effort", eff)
                self.likert[dom] = (inf, eff)
                self.enter_next()
            elif kind == "test":
                self._keyboard_test()
            elif kind == "demographics":
                self.tab_to("e.name === 'age'")
                page.keyboard.type("34")
                self.choose("gender", 3)  # Non-binary
                self.tab_to("e.name === 'education'")
                for _ in range(5):  # "-", then down to "Master's degree"
                    page.keyboard.press("ArrowDown")
                assert page.eval_on_selector("select[name=education]", "s => s.value") == \
                    "Master's degree"
                self.enter_next()
            elif kind in ("complete", "screened_out"):
                return
            else:  # pragma: no cover
                raise AssertionError(f"unexpected page {kind}")

    def _play(self, k: int) -> None:
        self.page.wait_for_selector(f"#board[data-demo='{k}']")
        self.tab_to("e.id === 'play'")
        self.page.keyboard.press("Enter")
        self.page.wait_for_selector("#play[data-state='done']")

    def _keyboard_test(self) -> None:
        page = self.page
        st = self.state()["step"]
        key = (st["domain"], st["trial"])
        test = next(t for ts in self.study["tests"][st["domain"]] for t in ts
                    if t["game"]["states"] == st["game"]["states"] and t["layout"] == st["layout"])
        weights = self.study["domain_info"][st["domain"]]["weights"]
        moves = best_path(test["game"], weights) if st["trial"] % 2 else shortest_path(st["game"])
        # the game has the focus when the page opens; its keys play it
        assert page.evaluate("document.activeElement.id") == "board"
        self.press(moves)
        page.wait_for_selector("#board[data-ended='true']")
        assert page.get_attribute("#board", "data-moves") == " ".join(moves)
        conf = 1 + (st["trial"] % 5)
        self.choose("confidence", conf)  # the arrows no longer go to the finished game
        assert page.get_attribute("#board", "data-moves") == " ".join(moves)
        self.played[key] = moves
        self.confidence[key] = conf
        self.enter_next()


def test_keyboard_only_participant_and_axe_on_every_page(browser, toy_study,  # noqa: ANN001
                                                        tmp_path) -> None:  # noqa: ANN001
    who, out, _ = _run(browser, toy_study, tmp_path, make=KeyboardParticipant)
    test_study_browser._check_export(who, out)  # every answer as chosen by keyboard
    (p,) = _rows(out / "participants.csv")
    assert (p["age"], p["gender"], p["education"]) == ("34", "Non-binary", "Master's degree")
    kinds = {"consent", "instructions", "free_play", "practice", "post_practice",
             "domain_intro", "demos", "survey", "test", "feedback", "demographics"}
    assert set(who.checked) == kinds
    assert {k: v for k, v in who.checked.items() if v} == {}


@pytest.mark.parametrize("status", ["declined", "screened_out", "complete"])
def test_axe_on_the_pages_that_end_a_study(browser, toy_study, tmp_path,  # noqa: ANN001
                                           status: str) -> None:
    """A preview session (which never leaves for Prolific, so axe can take its time)."""
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'end.db'}", seed=3)
    with running(app) as base:
        ctx = browser.new_context(viewport={"width": 1000, "height": 700})
        page = ctx.new_page()
        page.goto(f"{base}/?mode=preview")
        page.wait_for_selector("main[data-step='consent']")
        if status == "declined":  # by keyboard: Tab to the button, Enter
            who = KeyboardParticipant(page, base, {})
            who.tab_to("e.id === 'decline'")
            page.keyboard.press("Enter")
        else:
            n = KeyboardParticipant(page, base, {}).state()["n_steps"]
            values = {"status": "screened_out"} if status == "screened_out" else {
                "step_index": n - 1}
            with app.state.service.Session() as db, db.begin():
                db.execute(update(Session).values(**values))
            page.reload()
        page.wait_for_selector(f"main[data-step='{status}'] #code")
        assert axe_problems(page) == []
        ctx.close()
    app.state.service.engine.dispose()
