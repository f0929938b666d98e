"""Database tables. Every participant action is one `events` row, written once, in order."""

from __future__ import annotations

from datetime import UTC, datetime

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


def utcnow() -> datetime:
    return datetime.now(UTC)


def aware(dt: datetime) -> datetime:
    """`dt` as UTC-aware (SQLite gives back naive datetimes; they were stored as UTC)."""
    return dt if dt.tzinfo else dt.replace(tzinfo=UTC)


class Base(DeclarativeBase):
    pass


class Session(Base):
    """One participant's attempt at the study (no IP address or other personal data)."""

    __tablename__ = "sessions"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    participant_id: Mapped[str] = mapped_column(String(32), unique=True)
    token: Mapped[str] = mapped_column(String(64), unique=True)
    study_version: Mapped[str] = mapped_column(String(32))
    pid_key: Mapped[str | None] = mapped_column(String(140), unique=True, nullable=True)
    prolific_pid: Mapped[str | None] = mapped_column(String(64), nullable=True)
    study_id: Mapped[str | None] = mapped_column(String(64), nullable=True)
    session_id: Mapped[str | None] = mapped_column(String(64), nullable=True)
    condition: Mapped[str] = mapped_column(String(32))
    domain_order: Mapped[str] = mapped_column(String(200))
    test_set: Mapped[int] = mapped_column(Integer)
    seed: Mapped[int] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(16), default="in_progress", index=True)
    is_preview: Mapped[bool] = mapped_column(Boolean, default=False)
    step_index: Mapped[int] = mapped_column(Integer, default=0)
    event_seq: Mapped[int] = mapped_column(Integer, default=0)
    practice_attempts: Mapped[int] = mapped_column(Integer, default=0)
    age: Mapped[int | None] = mapped_column(Integer, nullable=True)
    gender: Mapped[str | None] = mapped_column(String(40), nullable=True)
    education: Mapped[str | None] = mapped_column(String(40), nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    last_active_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    step_entered_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    completed_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class Event(Base):
    """One client event, identified by the client's event id (a retry cannot duplicate it)."""

    __tablename__ = "events"
    __table_args__ = (
        UniqueConstraint("session_pk", "seq", name="uq_events_session_seq"),
        UniqueConstraint("session_pk", "event_id", name="uq_events_session_event_id"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_pk: Mapped[int] = mapped_column(ForeignKey("sessions.id"), index=True)
    seq: Mapped[int] = mapped_column(Integer)
    event_id: Mapped[str] = mapped_column(String(64))
    step_index: Mapped[int] = mapped_column(Integer)
    step_kind: Mapped[str] = mapped_column(String(32))
    domain: Mapped[str | None] = mapped_column(String(64), nullable=True)
    type: Mapped[str] = mapped_column(String(32))
    payload: Mapped[dict] = mapped_column(JSON)
    client_ms: Mapped[float | None] = mapped_column(Float, nullable=True)
    server_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    # demo_play_end only: the play's length on the server's clock (from the matching
    # demo_play_start; empty without one) and whether it counts as watched to the end.
    server_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    verified: Mapped[bool | None] = mapped_column(Boolean, nullable=True)


class TestResponse(Base):
    """A scored test answer: the server's replay of the participant's moves."""

    __tablename__ = "test_responses"
    __table_args__ = (UniqueConstraint("session_pk", "test_id", name="uq_test_session_test"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_pk: Mapped[int] = mapped_column(ForeignKey("sessions.id"), index=True)
    event_pk: Mapped[int] = mapped_column(ForeignKey("events.id"))
    domain: Mapped[str] = mapped_column(String(64))
    domain_position: Mapped[int] = mapped_column(Integer)
    test_id: Mapped[str] = mapped_column(String(100))
    difficulty: Mapped[str] = mapped_column(String(16))
    overlap: Mapped[float | None] = mapped_column(Float, nullable=True)
    trial_index: Mapped[int] = mapped_column(Integer)
    actions: Mapped[str] = mapped_column(Text)
    n_actions: Mapped[int] = mapped_column(Integer)
    reward: Mapped[float] = mapped_column(Float)
    optimal_reward: Mapped[float] = mapped_column(Float)
    optimal: Mapped[bool] = mapped_column(Boolean)
    optimal_length: Mapped[int] = mapped_column(Integer)
    time_ms: Mapped[int] = mapped_column(Integer)  # the browser's figure (client_time_ms)
    server_ms: Mapped[int] = mapped_column(Integer)  # server clock (exported as time_ms)
    confidence: Mapped[int] = mapped_column(Integer)


class ClientReport(Base):
    """A request the server refused for good, as the participant's page reported it.

    The page keeps a refused event until the server has stored it here, so no answer is lost
    even when it could not be accepted (the researcher sees what was sent and why it failed).
    """

    __tablename__ = "client_reports"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    report_id: Mapped[str] = mapped_column(String(64), unique=True)
    session_pk: Mapped[int | None] = mapped_column(ForeignKey("sessions.id"), index=True,
                                                   nullable=True)
    path: Mapped[str] = mapped_column(String(100))
    http_status: Mapped[int] = mapped_column(Integer)
    error: Mapped[str] = mapped_column(String(64))
    detail: Mapped[str] = mapped_column(Text)
    event: Mapped[dict | None] = mapped_column(JSON, nullable=True)
    client_ms: Mapped[float | None] = mapped_column(Float, nullable=True)
    server_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class StudyVersion(Base):
    """The content of every study file the server has run, so a session started on one
    version is served from it to the end even after `study.json` changes."""

    __tablename__ = "study_versions"
    version: Mapped[str] = mapped_column(String(32), primary_key=True)
    title: Mapped[str] = mapped_column(String(200))
    content: Mapped[str] = mapped_column(Text)  # study.json as written by `study init`
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ClosedLoopItem(Base):
    """One item a closed-loop participant was shown (`closed_loop` condition).

    Written when the teacher decides the item (in the transaction that stored the answer
    before it) and completed when its own answer is stored. It is a record for the export:
    the teacher's state itself is rebuilt from the events alone (`cfteach.study.live`).
    """

    __tablename__ = "closed_loop_items"
    __table_args__ = (UniqueConstraint("session_pk", "domain", "position",
                                       name="uq_closed_loop_items_position"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    session_pk: Mapped[int] = mapped_column(ForeignKey("sessions.id"), index=True)
    domain: Mapped[str] = mapped_column(String(64))
    position: Mapped[int] = mapped_column(Integer)          # 0-based within the domain
    kind: Mapped[str] = mapped_column(String(16))           # demonstration | test | feedback
    purpose: Mapped[str] = mapped_column(String(16))        # lesson | remedial | diagnostic...
    demo: Mapped[int] = mapped_column(Integer)              # the pool's demo index
    about: Mapped[int | None] = mapped_column(Integer, nullable=True)
    env_code: Mapped[str] = mapped_column(String(64))
    env_index: Mapped[int] = mapped_column(Integer)
    start_state: Mapped[dict] = mapped_column(JSON)
    expected_area: Mapped[float] = mapped_column(Float)     # belief when the item was chosen
    predicted_optimal: Mapped[float | None] = mapped_column(Float, nullable=True)
    predicted_held_out: Mapped[float | None] = mapped_column(Float, nullable=True)
    # share of the teaching done when the item was chosen (the page's progress bar)
    progress: Mapped[float | None] = mapped_column(Float, nullable=True)
    shown_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    done_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    server_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    actions: Mapped[str | None] = mapped_column(Text, nullable=True)   # tests: the answer
    reward: Mapped[float | None] = mapped_column(Float, nullable=True)
    optimal_reward: Mapped[float | None] = mapped_column(Float, nullable=True)
    optimal: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
