"""Chromium plays a whole closed-loop session with the keyboard: it answers the first
diagnostic test wrongly on purpose, sees the feedback page (its answer beside Chip's, both
energies, where they part and what the difference cost, checked against a replay with the
domain's own `step`), then the next demonstration; the export then replays offline,
through `ClosedLoopTeacher`, to the very items the page showed. Every item kind is checked
with axe-core."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from sqlalchemy import select

import test_study_browser
from cfteach.closedloop import ClosedLoopTeacher
from cfteach.study.build import init_study, preview_sources
from cfteach.study.feedback import MINUS
from cfteach.study.games import best_path, replay
from cfteach.study.layout import instance_layout
from cfteach.study.live import pool_from_cell, settings_of
from cfteach.study.models import ClosedLoopItem
from cfteach.study.texts import FEATURE_PHRASES
from test_study_a11y_browser import axe_problems

pytestmark = [pytest.mark.browser, pytest.mark.slow]
browser = test_study_browser.browser


@pytest.fixture(scope="module")
def cl_only_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cl_browser")
    init_study(out, preview_sources(["skateboard"]), demo_step_ms=30,
               conditions=["closed_loop"], teacher={"n_particles": 300, "max_items": 9},
               completion_code="C0MPL3TE", screened_out_code="SCR33N")
    return out


def _wrong_moves(game: dict, weights: list[float]) -> list[str]:
    """A finished answer worse than the best one: a detour, then the best path."""
    best = best_path(game, weights)
    top = replay(game, weights, best).reward
    acts = game["actions"]
    for a, b in (("up", "down"), ("down", "up"), ("left", "right"), ("right", "left")):
        j = game["next"][0][acts.index(a)]
        if j == 0 or game["terminal"][j] or game["next"][j][acts.index(b)] != 0:
            continue
        moves = [a, b] + best
        if replay(game, weights, moves).reward < top - 1e-9:
            return moves
    raise AssertionError("no wrong answer found for this test")


class ClosedLoopParticipant(test_study_browser.Participant):
    """Plays the teaching phase item by item; the rest as every participant does."""

    app = None  # set by the test: the in-process server (to know the test's best answer)
    shown: list[tuple[int, str]]

    def run(self, **kw) -> None:  # noqa: ANN003
        self.shown = []
        super().run(stop_at="closed_loop")
        self._teaching()
        super().run(**kw)

    def _pending(self) -> ClosedLoopItem:
        svc = self.app.state.service
        with svc.Session() as db:
            return db.scalar(select(ClosedLoopItem).where(ClosedLoopItem.done_at.is_(None))
                             .order_by(ClosedLoopItem.position).limit(1))

    def _teaching(self) -> None:
        page = self.page
        wrong_done = False
        self.axe: dict[str, list[str]] = {}
        while self.step() == "closed_loop":
            kind = page.get_attribute("#cl-item", "data-kind")
            pos = int(page.get_attribute("#cl-item", "data-position"))
            self.shown.append((pos, kind))
            if kind not in self.axe:
                self.axe[kind] = axe_problems(page)
            if kind == "demonstration":
                assert page.is_disabled("#next")
                page.click("#play")
                page.wait_for_selector("#board[data-watched='true']")
            elif kind == "test":
                if not wrong_done:  # a reload mid-game lands on the same item, game restarted
                    page.click("#board")
                    self.press(["up"])
                    page.reload()
                    page.wait_for_selector("main[data-step='closed_loop'] #cl-item",
                                           state="attached")
                    assert page.get_attribute("#cl-item", "data-position") == str(pos)
                    assert page.get_attribute("#cl-item", "data-kind") == "test"
                    assert page.get_attribute("#board", "data-moves") == ""
                    self.reloaded = pos
                svc = self.app.state.service
                item = self._pending()
                game = svc.live.game(svc.study, "skateboard", item.demo)
                weights = svc.study["domain_info"]["skateboard"]["weights"]
                moves = best_path(game, weights) if wrong_done else _wrong_moves(game, weights)
                page.click("#board")
                assert page.is_disabled("#next")
                self.press(moves)
                page.wait_for_selector("#board[data-ended='true']")
                assert page.get_attribute("#board", "data-moves") == " ".join(moves)
                if not wrong_done:
                    self.wrong = (pos, moves)
                wrong_done = True
            else:  # feedback: both boards animate; Continue once they have played
                assert (pos - 1, "test") in self.shown
                assert page.is_visible("#answer-board") and page.is_visible("#optimal-board")
                assert "Chip's best answer" in page.text_content("#feedback-text")
                _check_feedback(self)
                self.feedback_seen = pos
            page.click("#next:not([disabled])")
            page.wait_for_function(
                "([p]) => document.querySelector('main').dataset.step !== 'closed_loop' || "
                "Number(document.querySelector('#cl-item')?.dataset.position) === p + 1",
                arg=[pos])


def _energy(text: str) -> float:
    """'Your answer: −3.5 energy' -> -3.5"""
    return float(text.split(": ")[1].split(" ")[0].replace(MINUS, "-"))


def _stepped(inst, start, actions: list[str], weights) -> tuple[float, list, list]:  # noqa: ANN001
    """Reward, feature counts and states of `actions`, stepped with the domain itself."""
    names = list(inst.domain.actions)
    s, states, mu = start, [start], [0.0] * len(weights)
    for a in actions:
        s, phi, _ = inst.step(s, names.index(a))
        mu = [m + float(f) for m, f in zip(mu, phi, strict=True)]
        states.append(s)
    return sum(w * m for w, m in zip(weights, mu, strict=True)), mu, states


def _check_feedback(self: ClosedLoopParticipant) -> None:
    """The feedback page against an independent replay of both answers."""
    page = self.page
    svc = self.app.state.service
    item = self._pending()
    ds = svc.live.pool(svc.study, "skateboard").ds
    inst, start = ds.instance(item.demo), ds.start_state(item.demo)
    info = svc.study["domain_info"]["skateboard"]
    game = svc.live.game(svc.study, "skateboard", item.demo)
    best = best_path(game, info["weights"])
    ra, mua, sa = _stepped(inst, start, self.wrong[1], info["weights"])
    rb, mub, sb = _stepped(inst, start, best, info["weights"])
    layout = instance_layout("skateboard", inst)
    page.wait_for_selector("#play[data-state='done']")  # the replay starts by itself
    assert _energy(page.text_content("#answer-energy")) == round(ra, 2)
    assert _energy(page.text_content("#optimal-energy")) == round(rb, 2)
    # where the routes part: the dashed square on both boards, at Chip's cell before it
    part = next(t for t in range(min(len(sa), len(sb))) if sa[t] != sb[t])
    cell = inst.state_to_json(sa[part - 1])["agent"]
    assert f"step {part}" in page.text_content("#feedback-part")
    for board in ("#answer-board", "#optimal-board"):
        marks = page.eval_on_selector_all(f"{board} [data-kind='part']", "l => l.length")
        assert marks == 1
        x, y = page.eval_on_selector(f"{board} [data-kind='part']",
                                     "e => [Number(e.getAttribute('x')), "
                                     "Number(e.getAttribute('y'))]")
        assert (x, y) == ((cell[0] - 1) * 64 + 3, (layout["height"] - cell[1]) * 64 + 3)
    # the sentence names the costliest feature and what it cost
    costs = [w * (a - b) for w, a, b in zip(info["weights"], mua, mub, strict=True)]
    k = min(range(len(costs)), key=costs.__getitem__)
    why = page.text_content("#feedback-why")
    assert FEATURE_PHRASES["skateboard"][info["feature_names"][k]] in why, why
    assert f"{round(costs[k], 2):g}".replace("-", MINUS) in why, why


def test_browser_closed_loop_session(browser, cl_only_study: Path,  # noqa: ANN001
                                     tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    made: list = []
    real = test_study_browser.create_app

    def create_app(*a, **k):  # noqa: ANN002, ANN003, ANN202
        made.append(real(*a, **k))
        ClosedLoopParticipant.app = made[-1]
        return made[-1]

    monkeypatch.setattr(test_study_browser, "create_app", create_app)
    who, out, _db = test_study_browser._run(browser, cl_only_study, tmp_path,
                                            make=ClosedLoopParticipant)
    kinds = [k for _, k in who.shown]
    assert set(who.axe) == {"demonstration", "test", "feedback"}
    assert {k: v for k, v in who.axe.items() if v} == {}
    assert [p for p, _ in who.shown] == list(range(len(who.shown)))
    wrong_pos, wrong_moves = who.wrong
    assert who.reloaded == wrong_pos
    # the wrong answer got feedback next, then a (remedial or next) lesson
    assert who.shown[wrong_pos + 1] == (wrong_pos + 1, "feedback")
    assert who.feedback_seen == wrong_pos + 1
    assert kinds[wrong_pos + 2] == "demonstration"
    with open(out / "closed_loop_items.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [(int(r["position"]), r["kind"]) for r in rows] == who.shown
    assert rows[wrong_pos]["actions"].split() == wrong_moves
    assert rows[wrong_pos]["optimal"] == "0" and float(rows[wrong_pos]["regret"]) > 0
    # offline: the export's answers through the same teacher give the same items
    study = json.loads((cl_only_study / "study.json").read_text())
    cell = study["closed_loop"]["skateboard"]
    pool = pool_from_cell(cell)
    responses = [{"actions": r["actions"].split()} if r["kind"] == "test" else {}
                 for r in rows]
    t = ClosedLoopTeacher.replay(pool, responses, settings=settings_of(cell),
                                 seed=int(rows[0]["teacher_seed"]))
    assert [(it.index, it.kind, it.purpose) for it in t.items] == \
        [(int(r["position"]), r["kind"], r["purpose"]) for r in rows]
    assert [it.to_json(pool)["start_state"] for it in t.items] == \
        [json.loads(r["start_state"]) for r in rows]
    with open(out / "test_responses.csv", newline="", encoding="utf-8") as f:
        assert len(list(csv.DictReader(f))) == 6  # then the same post-teaching tests

