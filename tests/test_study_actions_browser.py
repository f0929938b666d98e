"""Chromium plays a study whose domain declares `exit` on the "x" key: the legend names the
key and its label, the key press plays the action, and the export holds the moves."""

from __future__ import annotations

from pathlib import Path

import pytest

from actions_fixtures import ExitDomain
from cfteach.study.build import init_study, preview_sources
from cfteach.study.screenshots import KEYS
from test_study_browser import Participant, _rows, _run, browser  # noqa: F401

pytestmark = [pytest.mark.browser, pytest.mark.slow]


class ExitParticipant(Participant):
    """Presses each action's declared key, read from the page data, and checks the legend
    and, after each demonstration that ends with `exit`, the caption naming it."""

    def _demos(self) -> None:
        demos = self.state()["step"]["demos"]
        self.captions: list[str] = []
        original = self.page.click

        def click(selector: str, **kw) -> None:  # noqa: ANN003
            k = int(self.page.get_attribute("#board", "data-demo") or 0)
            original(selector, **kw)
            if selector == "#play":
                last = len(demos[k]["states"]) - 1
                self.page.wait_for_selector(f"#board[data-demo='{k}'][data-frame='{last}']")
                text = self.page.text_content("#demo-action")
                want = "Chip: leave the game" if demos[k]["actions"][-1] == "exit" else ""
                assert text == want
                self.captions.append(text)

        self.page.click = click
        try:
            super()._demos()
        finally:
            self.page.click = original

    def press(self, moves: list[str]) -> None:
        step = self.state()["step"]
        keys = {c["action"]: c["key"] for c in step.get("info", step).get("controls", [])}
        if step["kind"] == "test":
            legend = self.page.text_content("table.keys tr[data-action='exit']")
            assert legend == "xleave the game"
        for m in moves:
            self.page.keyboard.press(keys.get(m) or KEYS[m])


def test_browser_plays_a_declared_exit_action(browser, tmp_path: Path) -> None:  # noqa: ANN001, F811
    folder = tmp_path / "study"
    init_study(folder, preview_sources([ExitDomain()], demos=2), demo_step_ms=15,
               completion_code="C0MPL3TE")
    who, out, _ = _run(browser, folder, tmp_path, make=ExitParticipant)
    assert "Chip: leave the game" in who.captions  # a demonstration ended with exit
    rows = _rows(out / "test_responses.csv")
    assert len(rows) == 6
    assert {(r["domain"], int(r["trial_index"])): r["actions"].split() for r in rows} \
        == who.played
    best = [r for r in rows if int(r["trial_index"]) % 2]  # played Chip's best path
    assert best and all(r["actions"].split()[-1] == "exit" and r["optimal"] == "1"
                        for r in best)
