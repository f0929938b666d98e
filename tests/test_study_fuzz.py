"""Fuzz the study's JSON API from its own OpenAPI schema (Schemathesis, in process).

Runs on a temporary SQLite toy study, and on PostgreSQL too where `CFTEACH_TEST_POSTGRES_URL`
is set (`postgres` marker).

Every operation gets schema-valid and schema-invalid requests, with no session, with a
made-up one and with live sessions standing on every kind of page. Each response must not be
a 5xx, must have a status the schema lists for that route and a body matching the schema, and
invalid input must be refused. Schema-valid input may only be refused for what the schema
cannot state: an event type the current page does not take, moves a game does not allow.

Bounded and derandomized so the normal test run stays short and stable; set
CFTEACH_FUZZ_EXAMPLES (per operation and mode) and CFTEACH_FUZZ_RANDOM=1 to search longer.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import schemathesis
from fastapi import FastAPI
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from schemathesis import GenerationMode
from schemathesis.specs.openapi.checks import negative_data_rejection, positive_data_acceptance

import test_study_support
from cfteach.study.bot import run_participant
from cfteach.study.models import Session
from cfteach.study.schemas import PAYLOADS
from cfteach.study.server import create_app

toy_study = test_study_support.toy_study  # shared fixture

EXAMPLES = int(os.environ.get("CFTEACH_FUZZ_EXAMPLES", "80"))
RANDOM = os.environ.get("CFTEACH_FUZZ_RANDOM", "") == "1"
RESEARCHER = "fuzz-researcher-token"
# Live sessions are left on the first page of each of these kinds.
KINDS = ("consent", "practice", "domain_intro", "demos", "survey", "test", "feedback",
         "demographics")
# Refusals of schema-valid events that depend on the session's state or the game.
STATEFUL_422 = {"wrong_event_type", "bad_moves", "unknown_demo"}

OPERATIONS = [("POST", "/api/session"), ("GET", "/api/state"), ("POST", "/api/event"),
              ("POST", "/api/client-report"), ("GET", "/api/researcher/progress"),
              ("GET", "/researcher"), ("GET", "/"), ("GET", "/favicon.ico")]


@pytest.fixture(scope="module",
                params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def app(request: pytest.FixtureRequest, toy_study: Path,
        tmp_path_factory: pytest.TempPathFactory) -> Iterator[FastAPI]:
    """The server on a fresh SQLite file, and on PostgreSQL where it is available (NUL in a
    text column fails only there)."""
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path_factory.mktemp('fuzz') / 'study.db'}"
    else:
        url = test_study_support.fresh_postgres()
    # Rate limits off: the fuzzer sends hundreds of requests from one address.
    app = create_app(toy_study, url, researcher_token=RESEARCHER, seed=3,
                     sessions_per_minute=0, events_per_minute=0, auth_failures_per_minute=0,
                     reports_per_minute=0)
    yield app
    app.state.service.engine.dispose()


@pytest.fixture(scope="module")
def api(app: FastAPI) -> Any:
    schema = schemathesis.openapi.from_dict(app.openapi())
    schema.app = app  # requests go to the ASGI app in process, never over the network
    return schema


@pytest.fixture(scope="module")
def live_tokens(app: FastAPI) -> list[str]:
    """Sessions standing on each kind of page (events for them reach the step machine)."""
    client = TestClient(app)
    tokens = []
    for i, kind in enumerate(KINDS):
        params = {"prolific_pid": f"FUZZ{i:04d}", "study_id": "F"}
        token = client.post("/api/session", json=params).json()["token"]
        out = run_participant(client, params, token=token, stop_after=_first(app, token, kind))
        assert out["state"]["step"]["kind"] == kind
        tokens.append(token)
    return tokens


def _first(app: FastAPI, token: str, kind: str) -> int:
    """Index of the session's first page of this kind (each advancing event moves one)."""
    service = app.state.service
    with service.Session() as db:
        row = db.query(Session).filter_by(token=token).one()
        return [s["kind"] for s in service.steps(row)].index(kind)


def _run(api: Any, method: str, path: str, mode: GenerationMode, tokens: list[str]) -> int:
    """Send EXAMPLES generated requests for one operation; returns how many were sent."""
    op = api[path][method]
    client = TestClient(op.schema.app)
    sent = [0]
    # None: the generated header as is; else one of the live sessions.
    pick = st.sampled_from([None, *tokens]) if tokens else st.just(None)

    @given(case=op.as_strategy(generation_mode=mode), token=pick)
    @settings(max_examples=EXAMPLES, deadline=None, database=None, derandomize=not RANDOM,
              suppress_health_check=list(HealthCheck))
    def check(case: Any, token: str | None) -> None:
        if token is not None:
            case.headers = {**(case.headers or {}), "X-Session-Token": token}
            if path == "/api/event" and mode is GenerationMode.POSITIVE:
                now = client.get("/api/state", headers={"X-Session-Token": token}).json()
                case.body["step_index"] = now["step_index"]  # land on the live page
        response = case.call()
        excluded = [positive_data_acceptance]
        if response.status_code == 413:  # over the body limit: refused before any parsing,
            excluded.append(negative_data_rejection)  # which is a rejection too
        case.validate_response(response, excluded_checks=excluded)
        sent[0] += 1
        if mode is GenerationMode.POSITIVE and response.status_code in (400, 422):
            error = response.json().get("error")
            assert (method, path) == ("POST", "/api/event") and error in STATEFUL_422, (
                f"schema-valid request refused: {response.status_code} {response.text}")

    check()
    return sent[0]


# Schema-invalid requests exist only where there is a body (headers and the query here are
# optional strings: anything goes).
CASES = [(m, p, GenerationMode.POSITIVE) for m, p in OPERATIONS] + [
    (m, p, GenerationMode.NEGATIVE) for m, p in OPERATIONS if m == "POST"]


@pytest.mark.parametrize(("method", "path", "mode"), CASES,
                         ids=[f"{m} {p} {g.value}" for m, p, g in CASES])
def test_fuzz_api(api: Any, live_tokens: list[str], method: str, path: str,
                  mode: GenerationMode) -> None:
    session_routes = ("/api/state", "/api/event", "/api/client-report")
    sent = _run(api, method, path, mode, live_tokens if path in session_routes else [])
    assert sent >= 1


# Regression tests for what the fuzzer found (each failed before its fix).


def test_non_ascii_researcher_token_is_refused_not_a_crash(app: FastAPI) -> None:
    """hmac.compare_digest raised TypeError (a 500) on a non-ASCII token."""
    client = TestClient(app, raise_server_exceptions=False)
    r = client.get("/researcher", params={"token": "jeton-été"})
    assert r.status_code == 403 and r.json()["error"] == "forbidden"
    r = client.get("/api/researcher/progress",
                   headers={"X-Researcher-Token": "clé".encode("latin-1")})
    assert r.status_code == 403 and r.json()["error"] == "forbidden"
    assert client.get("/researcher", params={"token": RESEARCHER}).status_code == 200


def test_schema_states_which_prolific_ids_are_valid(app: FastAPI) -> None:
    """The server refused ids the schema allowed (no pattern in the schema); now they agree."""
    props = app.openapi()["components"]["schemas"]["SessionRequest"]["properties"]
    pattern = props["prolific_pid"]["anyOf"][0]["pattern"]
    client = TestClient(app)
    for pid in ("abc_DEF-1", "{{%PROLIFIC_PID%}}", "", "<script>", "\u00dbq", "a b", "{%X%}",
                "{{%A\nB%}}"):
        r = client.post("/api/session", json={"prolific_pid": pid, "study_id": "IDS"})
        assert (r.status_code == 200) == bool(re.match(pattern, pid)), (pid, r.text)
        if r.status_code != 200:
            assert r.status_code == 422 and "prolific_pid" in r.json()["detail"]
            if "\n" not in pid:  # the page's "link looks incomplete" message keys on it
                assert r.json()["error"] == "bad_parameter" and "PROLIFIC_PID" in r.text


def test_schema_states_each_event_type_and_its_payload(app: FastAPI) -> None:
    """The schema said any `type` and any payload object; the server took nine types with
    one payload shape each. Now the body is one variant per type, refused before the token."""
    body = app.openapi()["paths"]["/api/event"]["post"]["requestBody"]["content"][
        "application/json"]["schema"]
    assert set(body["discriminator"]["mapping"]) == set(PAYLOADS)
    client = TestClient(app)
    r = client.post("/api/event", json={"event_id": "abcdefgh1", "step_index": 0,
                                        "type": "hack"})
    assert r.status_code == 422 and "'hack'" in r.json()["detail"]
    r = client.post("/api/event", json={"event_id": "abcdefgh2", "step_index": 0,
                                        "type": "consent", "payload": {"adult": True}})
    assert r.status_code == 422 and "payload.read" in r.json()["detail"]


def test_every_refusal_has_the_documented_error_body(app: FastAPI) -> None:
    """422s were documented as FastAPI's HTTPValidationError (a list) but sent
    {error, detail}; 401/403/409/410/413/415/429 and the favicon's 204 were undocumented;
    unreadable bodies and unknown paths answered {detail} only."""
    paths = app.openapi()["paths"]
    event = paths["/api/event"]["post"]["responses"]
    assert {"401", "409", "410", "413", "415", "422", "429"} <= set(event)
    assert event["422"]["content"]["application/json"]["schema"]["required"] == [
        "error", "detail"]
    assert set(paths["/api/state"]["get"]["responses"]) >= {"200", "401", "410"}
    assert set(paths["/favicon.ico"]["get"]["responses"]) == {"204"}
    client = TestClient(app)
    deep = "[" * 20_000 + "]" * 20_000  # valid JSON the parser cannot read (too deep)
    r = client.post("/api/session", content=deep, headers={"Content-Type": "application/json"})
    assert r.status_code == 400 and sorted(r.json()) == ["detail", "error"]
    r = client.get("/api/nothing")
    assert r.status_code == 404 and sorted(r.json()) == ["detail", "error"]
    r = client.put("/api/event", json={})
    assert r.status_code == 405 and "POST" in r.headers["allow"] and r.json()["error"]


def test_numbers_are_json_numbers(app: FastAPI, live_tokens: list[str]) -> None:
    """Pydantic's lax mode took "0", true and false where the schema says integer or
    number (a client_ms of false was stored as 0.0), and 1 for true; now they are refused,
    while 0.0 stays an integer as in JSON Schema."""
    client = TestClient(app)
    base = {"event_id": "typecheck1", "step_index": 0, "type": "continue", "payload": {}}
    for field, value in (("step_index", "0"), ("step_index", True), ("client_ms", False)):
        r = client.post("/api/event", json={**base, field: value})
        assert r.status_code == 422 and field in r.json()["detail"], (field, value, r.text)
    consent = {"adult": 1, "read": True, "agree": True}
    r = client.post("/api/event", json={**base, "type": "consent", "payload": consent})
    assert r.status_code == 422 and "adult" in r.json()["detail"]
    r = client.post("/api/event", json={**base, "step_index": 0.0})
    assert r.status_code == 401  # well-formed: refused only for the missing session
    r = client.post("/api/client-report", json={"report_id": "typecheck2", "path": "/",
                                                 "http_status": 500, "client_ms": False})
    assert r.status_code == 422 and "client_ms" in r.json()["detail"]
    token = live_tokens[KINDS.index("survey")]
    step = client.get("/api/state", headers={"X-Session-Token": token}).json()["step_index"]
    r = client.post("/api/event", headers={"X-Session-Token": token}, json={
        "event_id": "typecheck3", "step_index": step, "type": "likert",
        "payload": {"informativeness": "3", "mental_effort": 2}})
    assert r.status_code == 422 and "informativeness" in r.json()["detail"]


def test_schema_states_which_comments_are_refused(app: FastAPI) -> None:
    """Comments with control characters were refused though the schema allowed any string."""
    likert = app.openapi()["components"]["schemas"]["Likert"]["properties"]["comment"]
    assert not re.match(likert["pattern"], "a\x01b") and re.match(likert["pattern"], "a\tb\nc")


def test_control_characters_in_a_client_report_are_refused(app: FastAPI) -> None:
    """A NUL in a report's detail was a 500 on PostgreSQL (text columns cannot hold it)."""
    client = TestClient(app, raise_server_exceptions=False)
    for field in ("path", "error", "detail"):
        report = {"report_id": f"nul-{field}-1", "path": "/api/event", "http_status": 413,
                  field: "a\x00b"}
        r = client.post("/api/client-report", json=report)
        assert r.status_code == 422 and field in r.json()["detail"], (field, r.text)
    r = client.post("/api/client-report", json={"report_id": "nul-none-1", "path": "/api/event",
                                                 "http_status": 413, "detail": "two\nlines"})
    assert r.status_code == 200
