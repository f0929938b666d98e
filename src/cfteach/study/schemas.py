"""Request bodies. Everything a participant sends is validated here before it is looked at."""

from __future__ import annotations

import re
from typing import Annotated, Literal, Union

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    StringConstraints,
    ValidationInfo,
    create_model,
)
from pydantic_core import PydanticCustomError

from .controls import ACTION_NAME_PATTERN
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


# Prolific ids: letters, digits, '_' and '-', or an unfilled placeholder such as
# {{%PROLIFIC_PID%}} (a researcher's preview). The pattern is in the OpenAPI schema too,
# so a client (or a fuzzer) can tell a valid id from the schema alone.
ID_PATTERN = r"^(?:[A-Za-z0-9_-]*|\{\{?%[^\x00-\x1f\x7f-\x9f]*%\}?\})$"
_ID_RE = re.compile(ID_PATTERN)


def _prolific_id(value: str, info: ValidationInfo) -> str:
    if not _ID_RE.match(value):
        raise PydanticCustomError("bad_parameter", "{name} may contain only letters, digits, '_' "
                                  "and '-'", {"name": (info.field_name or "id").upper()})
    return value


TOKEN_PATTERN = r"^[A-Za-z0-9_-]{43}$"  # what secrets.token_urlsafe(32) gives
IdStr = Annotated[str, StringConstraints(max_length=64), AfterValidator(_single_line),
                  AfterValidator(_prolific_id), Field(json_schema_extra={"pattern": ID_PATTERN})]
TokenStr = Annotated[str, StringConstraints(pattern=TOKEN_PATTERN)]
# The same rule in the OpenAPI schema (the validator gives the clearer message).
_TEXT_SCHEMA = Field(json_schema_extra={"pattern": r"^[^\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f]*$"})
Comment = Annotated[str, StringConstraints(max_length=2000), AfterValidator(_text),
                    _TEXT_SCHEMA]
LongComment = Annotated[str, StringConstraints(max_length=4000), AfterValidator(_text),
                        _TEXT_SCHEMA]
_LINE_SCHEMA = Field(json_schema_extra={"pattern": r"^[^\x00-\x1f\x7f-\x9f]*$"})
Path100 = Annotated[str, StringConstraints(max_length=100), AfterValidator(_single_line),
                    _LINE_SCHEMA]
Code64 = Annotated[str, StringConstraints(max_length=64), AfterValidator(_single_line),
                   _LINE_SCHEMA]
# Any action name a domain may declare (the server replays moves in the game's own table and
# refuses names it does not have with 422 bad_moves).
Action = Annotated[str, StringConstraints(pattern=ACTION_NAME_PATTERN, max_length=40)]


def _integral(value: object) -> object:
    """2.0 is an integer in JSON Schema (strict pydantic would refuse it): pass it as 2."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


Int = BeforeValidator(_integral)
Likert5 = Annotated[int, Field(ge=1, le=5), Int]


class Strict(BaseModel):
    # Strict types, as JSON Schema has them: "2" and true are not integers, false is not a
    # number, 1 is not true (lax pydantic took all of these; found by the fuzzer).
    model_config = ConfigDict(extra="forbid", strict=True)


class SessionRequest(Strict):
    prolific_pid: IdStr | None = None
    study_id: IdStr | None = None
    session_id: IdStr | None = None
    mode: Literal["live", "test", "preview"] | None = None
    token: TokenStr | None = None


class EventRequest(Strict):
    event_id: Annotated[str, StringConstraints(min_length=8, max_length=64,
                                               pattern=r"^[A-Za-z0-9_-]+$")]
    step_index: Annotated[int, Field(ge=0, le=10_000), Int]
    type: Annotated[str, StringConstraints(max_length=32, pattern=r"^[a-z_]+$")]
    payload: dict = Field(default_factory=dict)
    client_ms: Annotated[float, Field(ge=0, le=1e15)] | None = None


class ClientReport(Strict):
    """What the page sends when the server refused one of its requests for good."""

    report_id: Annotated[str, StringConstraints(min_length=8, max_length=64,
                                                pattern=r"^[A-Za-z0-9_-]+$")]
    # text columns: no control characters (PostgreSQL cannot store NUL: a 500 before)
    path: Path100
    http_status: Annotated[int, Field(ge=0, le=599), Int]
    error: Code64 = ""
    detail: Comment = ""
    event: dict | None = None  # the refused event as sent (kept even if it was malformed)
    client_ms: Annotated[float, Field(ge=0, le=1e15)] | None = None


class Empty(Strict):
    pass


def _true(value: object) -> object:
    """Only JSON's true (pydantic's Literal[True] also takes 1 and 1.0, even when strict)."""
    if value is not True:
        raise PydanticCustomError("must_be_true", "Input should be true")
    return value


Checked = Annotated[Literal[True], BeforeValidator(_true)]


class Consent(Strict):
    adult: Checked
    read: Checked
    agree: Checked


class PracticeAttempt(Strict):
    actions: Annotated[list[Action], Field(max_length=300)]
    time_ms: Annotated[int, Field(ge=0, le=86_400_000), Int]


class DemoPlayStart(Strict):
    demo_index: Annotated[int, Field(ge=0, le=100), Int]


class DemoPlayEnd(Strict):
    demo_index: Annotated[int, Field(ge=0, le=100), Int]
    completed: bool
    watch_ms: Annotated[int, Field(ge=0, le=86_400_000), Int]


class Likert(Strict):
    informativeness: Likert5
    mental_effort: Likert5
    comment: Comment = ""


class TestAnswer(Strict):
    actions: Annotated[list[Action], Field(max_length=500)]
    time_ms: Annotated[int, Field(ge=0, le=86_400_000), Int]
    confidence: Likert5
    resets: Annotated[int, Field(ge=0, le=10_000), Int] = 0


class ItemDone(Strict):
    """The item on screen of a closed-loop teaching phase is done (`actions`: a test's)."""

    item: Annotated[int, Field(ge=0, le=1000), Int]
    actions: Annotated[list[Action], Field(max_length=500)] | None = None
    time_ms: Annotated[int, Field(ge=0, le=86_400_000), Int] | None = None


class Demographics(Strict):
    # Literals of the tuples below, built at run time: pydantic reads them, mypy cannot
    age: Annotated[int, Field(ge=18, le=120), Int]
    gender: Literal[tuple(GENDERS)]  # type: ignore[valid-type]
    education: Literal[tuple(EDUCATION)] | None = None  # type: ignore[valid-type]
    comments: LongComment = ""


PAYLOADS: dict[str, type[Strict]] = {
    "consent": Consent, "continue": Empty, "practice_attempt": PracticeAttempt,
    "demo_play_start": DemoPlayStart, "demo_play_end": DemoPlayEnd, "likert": Likert,
    "test_response": TestAnswer, "demographics": Demographics, "page_load": Empty,
    "decline": Empty, "item_done": ItemDone,
}


def _typed_event(type_: str, payload: type[Strict]) -> type[EventRequest]:
    """An EventRequest whose `type` is `type_` and whose payload is already validated."""
    required = any(f.is_required() for f in payload.model_fields.values())
    name = "".join(w.capitalize() for w in type_.split("_")) + "Event"
    # Literal of a runtime value: the checker cannot see it, pydantic builds it fine
    return create_model(name, __base__=EventRequest,
                        type=(Literal[type_], ...),  # type: ignore[arg-type]  # see above
                        payload=(payload, ... if required else Field(default_factory=payload)))


def as_request(event: EventRequest) -> EventRequest:
    """A validated body variant as the service takes events: the payload a plain dict."""
    if isinstance(event.payload, dict):
        return event
    return EventRequest.model_construct(**{**dict(event), "payload": event.payload.model_dump()})


# The body of POST /api/event: one variant per event type, chosen by `type`, so the OpenAPI
# schema states each type's payload and an unknown type or a bad payload is refused (422)
# before the session is looked at. Every variant is an EventRequest.
# (a Union built at run time: the checker cannot follow it; to it, an EventRequest)
EventBody = Annotated[Union[tuple(_typed_event(t, m) for t, m in PAYLOADS.items())],  # type: ignore[valid-type]  # noqa: UP007, E501
                      Field(discriminator="type")]
