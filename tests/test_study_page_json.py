"""Pages whose games are encoded once (`study.page_json`): the bytes a participant
receives are exactly those of encoding the whole page, on every page kind."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

import test_study_support
from cfteach.study import page_json
from cfteach.study.bot import run_participant
from cfteach.study.games import public_game
from cfteach.study.page_json import StaticGame, render_page, static_game
from cfteach.study.server import create_app

toy_study = test_study_support.toy_study


def plain(content: object) -> str:
    """What Starlette's JSONResponse writes, computed here on its own."""
    return json.dumps(content, ensure_ascii=False, allow_nan=False, separators=(",", ":"))


GAME = {"actions": ["up", "down"], "states": [[0, 1], [2, 3]], "next": [[1, 0], [1, 1]],
        "terminal": [False, True]}


def test_a_spliced_page_is_byte_for_byte_the_plain_encoding() -> None:
    game = StaticGame(GAME)
    page = {"status": "in_progress", "step": {"kind": "test", "layout": "é ✓ \"q\"",
                                              "game": game, "n_trials": 3}}
    ack = {"ok": True, "stored": 1, "state": page}
    assert render_page(page) == plain(page)
    assert render_page(ack) == plain(ack)
    # the splice replaces one stand-in only: a page holding a look-alike string is intact
    tricky = {"step": {"note": "\x00game-0000000000000000\x00", "game": game}}
    assert render_page(tricky) == plain(tricky)
    # the kept text is what is written (the game is not encoded again)
    kept = StaticGame(GAME)
    kept.text = '{"kept":true}'
    assert json.loads(render_page({"state": {"step": {"game": kept}}})) == {
        "state": {"step": {"game": {"kept": True}}}}
    # pages without a kept game take the plain path
    for other in ({"step": {"game": dict(GAME)}}, {"state": None}, [1, 2], {"x": 1.5}):
        assert render_page(other) == plain(other)


def test_a_game_is_kept_once_per_source_and_refuses_nan() -> None:
    source = {**GAME, "phi": [[0.5]]}
    first = static_game(source, public_game)
    assert static_game(source, public_game) is first
    assert dict(first) == public_game(source) and json.loads(first.text) == public_game(source)
    assert static_game(dict(source), public_game) is not first  # another object: made anew
    whole = static_game(source, dict)  # the same object shown another way: kept apart
    assert whole is not first and dict(whole) == source
    with pytest.raises(ValueError):
        StaticGame({**GAME, "states": [[math.nan]]})


def test_the_cache_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(page_json, "MAX_GAMES", 3)
    monkeypatch.setattr(page_json, "_games", {})
    sources = [dict(GAME) for _ in range(5)]
    for s in sources:
        static_game(s, public_game)
    assert 1 <= len(page_json._games) <= 3


def test_every_page_a_participant_receives_is_the_plain_encoding(
        toy_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(page_json, "_games", {})
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'p.db'}", seed=3)
    seen: dict[str, int] = {}

    class Checking:
        """The bot's client, checking each page's bytes against a fresh encoding."""

        def __init__(self, client: TestClient) -> None:
            self.client = client

        def _check(self, r: Any) -> Any:  # noqa: ANN401
            body = r.json()
            page = body.get("state", body)
            if isinstance(page, dict) and isinstance(page.get("step"), dict):
                kind = page["step"]["kind"]
                seen[kind] = seen.get(kind, 0) + ("game" in page["step"])
            assert r.content.decode() == plain(body)
            return r

        def get(self, *a: Any, **k: Any) -> Any:  # noqa: ANN401
            return self._check(self.client.get(*a, **k))

        def post(self, *a: Any, **k: Any) -> Any:  # noqa: ANN401
            return self._check(self.client.post(*a, **k))

    with TestClient(app) as client:
        run_participant(Checking(client), {"prolific_pid": "5f1c0ffee0ddba11c0ffee07",
                                           "study_id": "S1", "session_id": "X7"})
    app.state.service.engine.dispose()
    assert seen.get("test", 0) > 0 and seen.get("practice", 0) > 0
    assert len(page_json._games) >= 2  # the practice game and the tests' were kept
    assert "complete" in seen
