"""Request bodies. Everything a participant sends is validated here before it is looked at."""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, StringConstraints

from .texts import EDUCATION, GENDERS

# Control characters make no sense in an id or a typed answer, and PostgreSQL cannot store
# NUL at all: refuse them here (422) on every database. Free text keeps tab and line breaks.
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")
_TEXT_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f]")


def _unicode(s: str) -> str:
    try:
        s.encode("utf-8")
    except UnicodeEncodeError:  # a lone surrogate ("\ud800" in the JSON)
        raise ValueError("invalid Unicode (unpaired surrogate)") from None
    return s


def _single_line(s: str) -> str:
    if _CONTROL.search(s):
        raise ValueError("control characters (NUL, line breaks, ...) are not allowed")
    return _unicode(s)


def _text(s: str) -> str:
    if _TEXT_CONTROL.search(s):
        raise ValueError("control characters other than tab and line breaks are not allowed")
    return _unicode(s)


TOKEN_PATTERN = r"^[A-Za-z0-9_-]{43}$"  # what secrets.token_urlsafe(32) gives
IdStr = Annotated[str, StringConstraints(max_length=64), AfterValidator(_single_line)]
TokenStr = Annotated[str, StringConstraints(pattern=TOKEN_PATTERN)]
Comment = Annotated[str, StringConstraints(max_length=2000), AfterValidator(_text)]
LongComment = Annotated[str, StringConstraints(max_length=4000), AfterValidator(_text)]
Action = Literal["up", "down", "left", "right", "pickup", "dropoff"]
Likert5 = Annotated[int, Field(ge=1, le=5)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SessionRequest(Strict):
    prolific_pid: IdStr | None = None
    study_id: IdStr | None = None
    session_id: IdStr | None = None
    mode: Literal["live", "test", "preview"] | None = None
    token: TokenStr | None = None


class EventRequest(Strict):
    event_id: Annotated[str, StringConstraints(min_length=8, max_length=64,
                                               pattern=r"^[A-Za-z0-9_-]+$")]
    step_index: Annotated[int, Field(ge=0, le=10_000)]
    type: Annotated[str, StringConstraints(max_length=32, pattern=r"^[a-z_]+$")]
    payload: dict = Field(default_factory=dict)
    client_ms: Annotated[float, Field(ge=0, le=1e15)] | None = None


class ClientReport(Strict):
    """What the page sends when the server refused one of its requests for good."""

    report_id: Annotated[str, StringConstraints(min_length=8, max_length=64,
                                                pattern=r"^[A-Za-z0-9_-]+$")]
    path: Annotated[str, StringConstraints(max_length=100)]
    http_status: Annotated[int, Field(ge=0, le=599)]
    error: Annotated[str, StringConstraints(max_length=64)] = ""
    detail: Annotated[str, StringConstraints(max_length=2000)] = ""
    event: dict | None = None  # the refused event as sent (kept even if it was malformed)
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
    comment: Comment = ""


class TestAnswer(Strict):
    actions: Annotated[list[Action], Field(max_length=500)]
    time_ms: Annotated[int, Field(ge=0, le=86_400_000)]
    confidence: Likert5
    resets: Annotated[int, Field(ge=0, le=10_000)] = 0


class ItemDone(Strict):
    """The item on screen of a closed-loop teaching phase is done (`actions`: a test's)."""

    item: Annotated[int, Field(ge=0, le=1000)]
    actions: Annotated[list[Action], Field(max_length=500)] | None = None
    time_ms: Annotated[int, Field(ge=0, le=86_400_000)] | None = None


class Demographics(Strict):
    age: Annotated[int, Field(ge=18, le=120)]
    gender: Literal[tuple(GENDERS)]  # type: ignore[valid-type]
    education: Literal[tuple(EDUCATION)] | None = None  # type: ignore[valid-type]
    comments: LongComment = ""


PAYLOADS: dict[str, type[Strict]] = {
    "consent": Consent, "continue": Empty, "practice_attempt": PracticeAttempt,
    "demo_play_start": DemoPlayStart, "demo_play_end": DemoPlayEnd, "likert": Likert,
    "test_response": TestAnswer, "demographics": Demographics, "page_load": Empty,
    "decline": Empty, "item_done": ItemDone,
}
