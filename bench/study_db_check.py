"""What a study database holds after a load test, compared with what the simulated
participants were told (shared by bench_study_load.py and bench_closed_loop_study.py)."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import func, select

from cfteach.study.db import make_engine
from cfteach.study.models import ClosedLoopItem, Event, Session


@dataclass
class Stored:
    """Events stored per participant, who completed, and sessions whose event sequence or
    closed-loop items have gaps or repeats."""

    events: dict[str, int]
    completed: set[str]
    seq_gaps: int
    item_gaps: int

    def lost(self, acked: dict[str, int]) -> int:
        """Acknowledged events missing from the database."""
        return sum(max(0, n - self.events.get(p, 0)) for p, n in acked.items())

    def duplicated(self, acked: dict[str, int], in_flight: dict[str, int] | None = None) -> int:
        """Events stored beyond those acknowledged (and those still without an answer)."""
        in_flight = in_flight or {}
        return sum(max(0, self.events.get(p, 0) - n - in_flight.get(p, 0))
                   for p, n in acked.items())


def stored(db: str, *, skip_pid_prefix: str | None = None) -> Stored:
    """Read the counts from database `db` (sessions whose Prolific id starts with
    `skip_pid_prefix`, e.g. a benchmark's attackers, left out)."""
    engine = make_engine(db)
    keep = (Session.prolific_pid.is_(None) | Session.prolific_pid.not_like(f"{skip_pid_prefix}%")
            if skip_pid_prefix else Session.id.is_not(None))
    with engine.connect() as conn:
        events = dict(conn.execute(select(Session.participant_id, func.count(Event.id))
                                   .outerjoin(Event, Event.session_pk == Session.id)
                                   .where(keep).group_by(Session.participant_id)).all())
        completed = set(conn.scalars(select(Session.participant_id)
                                     .where(Session.status == "completed", keep)))
        gaps = conn.scalar(select(func.count()).select_from(
            select(Event.session_pk).group_by(Event.session_pk)
            .having((func.max(Event.seq) != func.count())
                    | (func.min(Event.seq) != 1)).subquery()))
        items = conn.scalar(select(func.count()).select_from(
            select(ClosedLoopItem.session_pk).group_by(
                ClosedLoopItem.session_pk, ClosedLoopItem.domain)
            .having(func.max(ClosedLoopItem.position) + 1 != func.count()).subquery()))
    engine.dispose()
    return Stored(events, completed, int(gaps or 0), int(items or 0))
