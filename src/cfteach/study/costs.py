"""What each event weighs against a session's event limit (`--events-per-minute`): about
the server work it can cause, relative to a page turn (1). A closed-loop answer leads to a
teacher decision in a worker; a play marker costs one small write, and must not be refused
while a participant watches (a refused play start would cost them the demonstration)."""

from __future__ import annotations

EVENT_COSTS = {
    "demo_play_start": 0.25,
    "demo_play_end": 0.25,
    "page_load": 0.5,
    "item_done": 4.0,
    "practice_attempt": 2.0,
    "test_response": 2.0,
}


def event_cost(event_type: str) -> float:
    return EVENT_COSTS.get(event_type, 1.0)
