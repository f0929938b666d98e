"""Page JSON with the games encoded once.

A test or practice page carries its game (states, moves, ends: 20 to 60 KB of JSON), the
same for every participant and every request, and every event's acknowledgement carries
the page it leads to. Encoding those games again on each request was about an eighth of the
web server's CPU under load (docs/study.md, "Load"). `static_game` keeps each game with its
JSON text; `PageResponse` splices that text into the page, so the bytes are exactly what
Starlette's `JSONResponse` writes (and as strict: no NaN or Infinity).
"""

from __future__ import annotations

import json
import secrets
import threading
from collections.abc import Callable
from typing import Any

from fastapi.responses import JSONResponse

#: Games kept at most (each with the object it was made from): a study has a few hundred.
MAX_GAMES = 4096
# Stands in for a game while the rest of the page is encoded; random per process, so no
# text a participant or a study file holds can be mistaken for it.
_MARK = f"\x00game-{secrets.token_hex(8)}\x00"
_MARK_JSON = json.dumps(_MARK)


def dumps(content: Any) -> str:  # noqa: ANN401
    """JSON as Starlette's `JSONResponse` writes it (compact, UTF-8, NaN refused)."""
    return json.dumps(content, ensure_ascii=False, allow_nan=False, indent=None,
                      separators=(",", ":"))


class StaticGame(dict):
    """A game as a page shows it, never changed once made, with its JSON text."""

    __slots__ = ("text",)

    def __init__(self, game: dict) -> None:
        super().__init__(game)
        self.text = dumps(self)


_games: dict[tuple[int, Callable[[dict], dict]], tuple[object, StaticGame]] = {}
_lock = threading.Lock()


def static_game(source: dict, public: Callable[[dict], dict]) -> StaticGame:
    """``public(source)`` as a `StaticGame`, made once per `source` object (a game in a
    loaded study, which lives as long as the server)."""
    key = (id(source), public)
    hit = _games.get(key)
    if hit is not None and hit[0] is source:
        return hit[1]
    game = StaticGame(public(source))
    with _lock:
        if len(_games) >= MAX_GAMES:
            _games.clear()
        _games[key] = (source, game)  # holding `source`: its id is not reused
    return game


def render_page(content: Any) -> str:  # noqa: ANN401
    """`content` as JSON; a page's `StaticGame` (``step.game``, or ``state.step.game`` in
    an acknowledgement) is spliced in from its text instead of being encoded again."""
    if not isinstance(content, dict):
        return dumps(content)
    state = content.get("state")
    page: dict = state if isinstance(state, dict) else content
    step = page.get("step")
    game = step.get("game") if isinstance(step, dict) else None
    if not isinstance(step, dict) or not isinstance(game, StaticGame):
        return dumps(content)
    marked_page = {**page, "step": {**step, "game": _MARK}}
    marked = {**content, "state": marked_page} if page is state else marked_page
    return dumps(marked).replace(_MARK_JSON, game.text, 1)


class PageResponse(JSONResponse):
    """A `JSONResponse` for pages and acknowledgements (`render_page`)."""

    def render(self, content: Any) -> bytes:  # noqa: ANN401
        return render_page(content).encode("utf-8")
