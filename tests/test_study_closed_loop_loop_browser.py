"""Chromium: a participant answers the first diagnostic test with a detour (``up down`` and
then the shortest path). The teacher v1 then showed feedback and demonstrations only until
`max_items` (the same one up to 24 times in a row). Now a test follows at least every
`test_every` items and no demonstration is shown more than `max_repeat` times in a row."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import select

import test_study_browser
import test_study_closed_loop_browser as base
from cfteach.closedloop import TeacherSettings
from cfteach.study import service
from cfteach.study.build import init_study, preview_sources
from cfteach.study.games import best_path
from cfteach.study.models import ClosedLoopItem

pytestmark = [pytest.mark.browser, pytest.mark.slow]
browser = test_study_browser.browser
SETTINGS = TeacherSettings()


@pytest.fixture(scope="module")
def two_condition_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`study init --preview --domains skateboard --conditions proposed,closed_loop`."""
    out = tmp_path_factory.mktemp("cl_loop_browser")
    init_study(out, preview_sources(["skateboard"]), demo_step_ms=20,
               conditions=["proposed", "closed_loop"],
               teacher={"n_particles": 300, "max_items": 16},
               completion_code="C0MPL3TE", screened_out_code="SCR33N")
    return out


class DetourParticipant(base.ClosedLoopParticipant):
    """Answers the first test with the detour, every later one with the shortest path."""

    def _teaching(self) -> None:
        page = self.page
        first = True
        self.reloaded = None
        while self.step() == "closed_loop":
            kind = page.get_attribute("#cl-item", "data-kind")
            pos = int(page.get_attribute("#cl-item", "data-position"))
            self.shown.append((pos, kind))
            if kind == "demonstration":
                page.click("#play")
                page.wait_for_selector("#board[data-watched='true']")
            elif kind == "test":
                svc = self.app.state.service
                item = self._pending()
                game = svc.live.game(svc.study, "skateboard", item.demo)
                weights = svc.study["domain_info"]["skateboard"]["weights"]
                moves = base._wrong_moves(game, weights) if first else best_path(game, weights)
                assert not first or moves[:2] in (["up", "down"], ["down", "up"],
                                                  ["left", "right"], ["right", "left"])
                page.click("#board")
                self.press(moves)
                page.wait_for_selector("#board[data-ended='true']")
                if first:
                    self.wrong = (pos, moves)
                first = False
            page.click("#next:not([disabled])")
            page.wait_for_function(
                "([p]) => document.querySelector('main').dataset.step !== 'closed_loop' || "
                "Number(document.querySelector('#cl-item')?.dataset.position) === p + 1",
                arg=[pos])


def test_a_detour_answer_does_not_make_the_live_teacher_loop(
        browser, two_condition_study: Path, tmp_path: Path,  # noqa: ANN001
        monkeypatch: pytest.MonkeyPatch) -> None:
    made: list = []
    real_app, real_cell = test_study_browser.create_app, service.choose_cell

    def create_app(*a, **k):  # noqa: ANN002, ANN003, ANN202
        made.append(real_app(*a, **k))
        DetourParticipant.app = made[-1]
        return made[-1]

    def closed_loop_cell(db, study, now, rng):  # noqa: ANN001, ANN202
        return ("closed_loop", *real_cell(db, study, now, rng)[1:])

    monkeypatch.setattr(test_study_browser, "create_app", create_app)
    monkeypatch.setattr(service, "choose_cell", closed_loop_cell)
    who, _out, _db = test_study_browser._run(browser, two_condition_study, tmp_path,
                                             make=DetourParticipant)
    kinds = [k for _, k in who.shown]
    wrong_pos, _ = who.wrong
    assert kinds[wrong_pos] == "test" and kinds[wrong_pos + 1] == "feedback"
    # after the first test: a test at least every `test_every` items
    gap = 0
    for k in kinds[wrong_pos + 1:]:
        gap = 0 if k == "test" else gap + 1
        assert gap <= SETTINGS.test_every, kinds
    assert kinds[wrong_pos + 1:].count("test") >= 1, kinds
    with made[-1].state.service.Session() as db:
        demos = [r.demo for r in db.scalars(select(ClosedLoopItem).where(
            ClosedLoopItem.kind == "demonstration").order_by(ClosedLoopItem.position))]
    for k in range(len(demos) - SETTINGS.max_repeat):
        assert len(set(demos[k:k + SETTINGS.max_repeat + 1])) > 1, demos
    assert len(kinds) <= 16
