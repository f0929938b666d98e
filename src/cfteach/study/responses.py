"""Response bodies of the JSON API, for its OpenAPI schema (the handlers build plain dicts).

The schema is what the fuzz test (tests/test_study_fuzz.py) checks every response against:
each route lists every status it can answer with, and every error has the same body.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict


class ErrorBody(BaseModel):
    """Every refusal: a stable machine-readable `error` and a one-line `detail` for people."""

    error: str
    detail: str


class SessionStarted(BaseModel):
    token: str
    resumed: bool
    participant_id: str


class Step(BaseModel):
    """The current page; which other fields it has depends on `kind`."""

    model_config = ConfigDict(extra="allow")
    kind: str


class State(BaseModel):
    status: str
    step_index: int
    n_steps: int
    participant_id: str
    is_preview: bool
    step: Step


class EventAck(BaseModel):
    """A stored event; practice attempts also say whether they passed."""

    model_config = ConfigDict(extra="allow")
    ok: bool
    state: State


class Ack(BaseModel):
    """A stored client report (`duplicate`: that report id was stored before)."""

    ok: bool
    duplicate: bool = False


class Cell(BaseModel):
    condition: str
    domain_order: str
    test_set: int
    occupied: int
    completed: int


class Progress(BaseModel):
    model_config = ConfigDict(extra="allow")  # a field added later is passed on, not dropped
    study_version: str
    status: dict[str, int]
    previews: int
    older_versions_in_progress: int
    cells: list[Cell]


_WHY = {
    400: "Unreadable request body",
    401: "Missing or unknown session token",
    403: "Researcher token required",
    409: "Conflicts with the session's state (duplicate event, wrong step, finished, "
         "session open elsewhere)",
    410: "The session belongs to another study version",
    413: "Request body too large",
    415: "Body is not application/json",
    422: "Invalid request (names the field and the problem)",
    408: "Request body not received in time",
    429: "Rate limited",
    503: "Stored but not yet confirmed on disk: retry (the retry's 409 confirms it)",
}


def errors(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """The `responses=` entry of a route that can refuse with these statuses.

    Always JSON, also on the HTML pages (so not FastAPI's `model=`, which would take the
    route's own media type).
    """
    content = {"application/json": {"schema": ErrorBody.model_json_schema()}}
    return {s: {"description": _WHY[s], "content": content} for s in statuses}
