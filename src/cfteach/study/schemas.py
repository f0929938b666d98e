"""Request bodies. Everything a participant sends is validated here before it is looked at."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StringConstraints

from .texts import EDUCATION, GENDERS

IdStr = Annotated[str, StringConstraints(max_length=64)]
Action = Literal["up", "down", "left", "right", "pickup", "dropoff"]
Likert5 = Annotated[int, Field(ge=1, le=5)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SessionRequest(Strict):
    prolific_pid: IdStr | None = None
    study_id: IdStr | None = None
    session_id: IdStr | None = None
    mode: Literal["live", "test", "preview"] | None = None
    token: Annotated[str, StringConstraints(max_length=64)] | None = None


class EventRequest(Strict):
    event_id: Annotated[str, StringConstraints(min_length=8, max_length=64,
                                               pattern=r"^[A-Za-z0-9_-]+$")]
    step_index: Annotated[int, Field(ge=0, le=10_000)]
    type: Annotated[str, StringConstraints(max_length=32)]
    payload: dict = Field(default_factory=dict)
    client_ms: Annotated[float, Field(ge=0, le=1e15)] | None = None


class Empty(Strict):
    pass


class Consent(Strict):
    adult: Literal[True]
    read: Literal[True]
    agree: Literal[True]


class PracticeAttempt(Strict):
    actions: Annotated[list[Action], Field(max_length=300)]
    time_ms: Annotated[int, Field(ge=0, le=86_400_000)]


class DemoPlayStart(Strict):
    demo_index: Annotated[int, Field(ge=0, le=100)]


class DemoPlayEnd(Strict):
    demo_index: Annotated[int, Field(ge=0, le=100)]
    completed: bool
    watch_ms: Annotated[int, Field(ge=0, le=86_400_000)]


class Likert(Strict):
    informativeness: Likert5
    mental_effort: Likert5
    comment: Annotated[str, StringConstraints(max_length=2000)] = ""


class TestAnswer(Strict):
    actions: Annotated[list[Action], Field(max_length=500)]
    time_ms: Annotated[int, Field(ge=0, le=86_400_000)]
    confidence: Likert5
    resets: Annotated[int, Field(ge=0, le=10_000)] = 0


class Demographics(Strict):
    age: Annotated[int, Field(ge=18, le=120)]
    gender: Literal[tuple(GENDERS)]  # type: ignore[valid-type]
    education: Literal[tuple(EDUCATION)] | None = None  # type: ignore[valid-type]
    comments: Annotated[str, StringConstraints(max_length=4000)] = ""


PAYLOADS: dict[str, type[Strict]] = {
    "consent": Consent, "continue": Empty, "practice_attempt": PracticeAttempt,
    "demo_play_start": DemoPlayStart, "demo_play_end": DemoPlayEnd, "likert": Likert,
    "test_response": TestAnswer, "demographics": Demographics, "page_load": Empty,
    "decline": Empty,
}
