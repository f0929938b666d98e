"""The statements every event runs, built once with bound parameters.

Building a SQLAlchemy select (coercing each column comparison) costs about as much as
running it on a small table; these run on every event, refused ones included (a refused
closed-loop answer must stay cheap: docs/study.md, "Tests and load"), so they are built at
import and only their parameters change."""

from __future__ import annotations

from sqlalchemy import bindparam, select

from .models import ClosedLoopItem, Event, Session

#: The session of a token (`token`).
SESSION_BY_TOKEN = select(Session).where(Session.token == bindparam("token"))
#: The same, locking the row until the transaction ends (PostgreSQL).
SESSION_BY_TOKEN_LOCKED = SESSION_BY_TOKEN.with_for_update()
#: An event already stored under this id (`pk`, `event_id`).
EVENT_BY_ID = select(Event.id).where(Event.session_pk == bindparam("pk"),
                                     Event.event_id == bindparam("event_id"))
#: The payloads of a step's verified play ends (`pk`, `step_index`).
VERIFIED_PLAY_ENDS = select(Event.payload).where(
    Event.session_pk == bindparam("pk"), Event.step_index == bindparam("step_index"),
    Event.type == "demo_play_end", Event.verified.is_(True))
#: The first closed-loop item of a domain without an answer (`pk`, `domain`).
PENDING_ITEM = select(ClosedLoopItem).where(
    ClosedLoopItem.session_pk == bindparam("pk"), ClosedLoopItem.domain == bindparam("domain"),
    ClosedLoopItem.done_at.is_(None)).order_by(ClosedLoopItem.position).limit(1)
