"""The FastAPI app: participant page + JSON API, researcher progress page."""

from __future__ import annotations

import hmac
import html
import secrets
from pathlib import Path

from fastapi import FastAPI, Header, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from . import schemas
from .config import StudyError, load_study
from .costs import event_cost
from .db import check_synchronous_commit, make_engine, upgrade
from .guard import BODY_TIMEOUT_S, Guard
from .page_json import PageResponse
from .ratelimit import RateLimiter
from .responses import Ack, EventAck, Progress, SessionStarted, State, errors
from .service import ApiError, StudyService, well_formed_token
from .sqlite_writes import NotDurable
from .versions import store_version, unstored_in_progress

HERE = Path(__file__).parent
# Refusals that mean "you did not prove who you are": counted per client address.
AUTH_FAILURES = {"no_session", "session_elsewhere", "forbidden"}


def _err(status: int, code: str, message: str) -> JSONResponse:
    return JSONResponse({"error": code, "detail": message}, status_code=status)


def create_app(study_dir: str | Path, db_url: str | None = None, *,
               researcher_token: str | None = None, seed: int | None = None,
               sessions_per_minute: int = 120, events_per_minute: int = 600,
               auth_failures_per_minute: int = 60,
               reports_per_minute: int = 60, states_per_minute: int = 120,
               new_version: bool = False, decision_workers: int = 0,
               allow_async_commit: bool = False,
               body_timeout_s: float = BODY_TIMEOUT_S) -> FastAPI:
    """Build the server for one study folder; migrations run here, before serving.

    Rate limits per minute (0 = off): new sessions per client address, events per session
    (weighted by the work each asks for: `costs.event_cost`), page reads per session,
    failed authentications per client address (beyond it, the address gets 429 before any
    token is looked up), error reports from the page per client address (a made-up token
    must not lift it). The client address is the connection's, or the one a trusted proxy
    forwards (see `livesrv.server_config`).

    The study file is kept in the database, so sessions started on an older file finish on
    it. Sessions in progress on a file the database does not hold (a database from before
    files were kept) would be stranded: refuse to start unless `new_version`.

    Closed-loop decisions run in `decision_workers` worker processes (0: one thread of this
    process). PostgreSQL must commit synchronously unless `allow_async_commit`. A request
    body not received within `body_timeout_s` is refused (408).
    """
    study = load_study(study_dir)
    if db_url is None:
        db_url = f"sqlite:///{Path(study_dir) / 'study.db'}"
    engine = make_engine(db_url)
    try:
        check_synchronous_commit(engine, allow_off=allow_async_commit)
    except ValueError as e:
        engine.dispose()
        raise StudyError(str(e)) from None
    upgrade(engine)
    stranded = unstored_in_progress(engine, study["version"])
    if stranded and not new_version:
        engine.dispose()
        which = ", ".join(f"{n} on version {v}" for v, n in sorted(stranded.items()))
        raise StudyError(f"{sum(stranded.values())} session(s) are in progress on a study file "
                         f"this database does not hold ({which}); serve that file until they "
                         "finish, or pass --new-version to start anyway (they cannot finish)")
    store_version(engine, study)
    # worker processes only where there is a teacher to run
    workers = decision_workers if study.get("closed_loop") else 0
    service = StudyService(engine, study, seed=seed, decision_workers=workers)
    service.live.warm(study)  # closed-loop lesson pools: derived from the file, built now
    token = researcher_token or secrets.token_urlsafe(16)
    session_limit = RateLimiter(sessions_per_minute)
    event_limit = RateLimiter(events_per_minute)
    auth_limit = RateLimiter(auth_failures_per_minute)
    report_limit = RateLimiter(reports_per_minute)
    state_limit = RateLimiter(states_per_minute)

    app = FastAPI(title="cfteach study", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.service = service
    app.state.researcher_token = token
    app.state.limits = {"sessions": session_limit, "events": event_limit, "auth": auth_limit,
                        "reports": report_limit, "states": state_limit}
    app.add_middleware(Guard, body_timeout_s=body_timeout_s)
    app.mount("/static", StaticFiles(directory=HERE / "static"), name="static")
    page = (HERE / "templates" / "index.html").read_text()

    @app.exception_handler(ApiError)
    async def _api_error(req: Request, e: ApiError) -> JSONResponse:
        if e.code in AUTH_FAILURES:
            auth_limit.hit(_client(req))
        return _err(e.status, e.code, e.message)

    @app.exception_handler(NotDurable)
    async def _not_durable(_req: Request, _e: NotDurable) -> JSONResponse:
        # stored and visible, but not confirmed on disk: neither "stored" nor "failed";
        # the page retries, and the retry's 409 confirms it once the disk does
        response = _err(503, "not_durable", "the request was received but could not be "
                        "confirmed on disk; retry it")
        response.headers["Retry-After"] = "1"
        return response

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(_req: Request, e: StarletteHTTPException) -> JSONResponse:
        # 400 unreadable body, 404, 405: the same body shape as every other refusal.
        response = _err(e.status_code, "http_error", str(e.detail))
        response.headers.update(e.headers or {})  # e.g. Allow on a 405
        return response

    @app.exception_handler(RequestValidationError)
    async def _bad_request(_req: Request, e: RequestValidationError) -> JSONResponse:
        err = e.errors()[0] if e.errors() else {"loc": (), "msg": "invalid request"}
        loc = ".".join(str(x) for x in err.get("loc", ()))
        # A malformed Prolific id keeps its own code: the page tells the participant that
        # the study link is incomplete.
        code = "bad_parameter" if err.get("type") == "bad_parameter" else "bad_request"
        return _err(422, code, f"{loc}: {err.get('msg')}")

    @app.get("/favicon.ico", status_code=204, response_class=Response)
    def favicon() -> Response:
        return Response(status_code=204)

    @app.get("/", response_class=HTMLResponse)
    def index() -> HTMLResponse:
        return HTMLResponse(page.replace("{{title}}", html.escape(study["title"])))

    def _not_blocked(request: Request) -> str:
        addr = _client(request)
        if auth_limit.blocked(addr):
            raise ApiError(429, "rate_limited", "too many failed authentications from this "
                           "address; try again in a minute")
        return addr

    def _session_token(request: Request, given: str | None) -> str:
        """The request's session token, refused (401) before any lookup if malformed."""
        _not_blocked(request)
        if not well_formed_token(given):
            raise ApiError(401, "no_session", "missing or malformed session token")
        return given

    @app.post("/api/session", response_model=SessionStarted,
              responses=errors(400, 409, 413, 415, 422, 429))
    def start(req: schemas.SessionRequest, request: Request) -> JSONResponse:
        addr = _not_blocked(request)
        if not session_limit.allow(addr):
            raise ApiError(429, "rate_limited", "too many new sessions; try again in a minute")
        row, resumed = service.start(req)
        return JSONResponse({"token": row.token, "resumed": resumed,
                             "participant_id": row.participant_id})

    @app.get("/api/state", response_model=State, responses=errors(401, 410, 422, 429, 503))
    async def state(request: Request, x_session_token: str | None = Header(default=None),
                    wait: float = Query(default=0.0, ge=0.0, le=5.0)) -> JSONResponse:
        """The page; `wait` (s) waits that long for a closed-loop item being prepared
        (holding no thread)."""
        tok = _session_token(request, x_session_token)
        if not state_limit.allow(tok):
            raise ApiError(429, "rate_limited", "too many page reads; slow down")
        return PageResponse(await service.state_async(tok, wait=wait))

    @app.post("/api/event", response_model=EventAck,
              responses=errors(400, 401, 408, 409, 410, 413, 415, 422, 429, 503))
    # EventBody is a Union built at run time (schemas.py): FastAPI reads it, mypy cannot
    async def event(req: schemas.EventBody, request: Request,  # type: ignore[valid-type]
                    x_session_token: str | None = Header(default=None)) -> JSONResponse:
        tok = _session_token(request, x_session_token)
        if not event_limit.allow(tok, cost=event_cost(req.type)):  # type: ignore[attr-defined]
            raise ApiError(429, "rate_limited", "too many events; slow down")
        return PageResponse(await service.post_event_async(tok, schemas.as_request(req)))

    @app.post("/api/client-report", response_model=Ack,
              responses=errors(400, 413, 415, 422, 429))
    def client_report(req: schemas.ClientReport, request: Request,
                      x_session_token: str | None = Header(default=None)) -> JSONResponse:
        if not report_limit.allow(_client(request)):
            raise ApiError(429, "rate_limited", "too many reports; slow down")
        # the session may be what failed: any token or none, but only a well-formed one is
        # looked up
        tok = x_session_token if well_formed_token(x_session_token) else None
        return JSONResponse(service.report(tok, req))

    def _check_researcher(request: Request, given: str | None) -> None:
        _not_blocked(request)
        if not given or not hmac.compare_digest(given.encode(), token.encode()):
            raise ApiError(403, "forbidden", "researcher token required")

    @app.get("/api/researcher/progress", response_model=Progress,
             responses=errors(403, 422, 429))
    def progress(request: Request,
                 x_researcher_token: str | None = Header(default=None)) -> dict:
        _check_researcher(request, x_researcher_token)
        return service.progress()

    @app.get("/researcher", response_class=HTMLResponse, responses=errors(403, 422, 429))
    def researcher(request: Request, token: str | None = None) -> HTMLResponse:
        _check_researcher(request, token)
        return HTMLResponse(_progress_html(service.progress(), study["title"]))

    return app


def _client(request: Request) -> str:
    return request.client.host if request.client else "?"


def _progress_html(p: dict, title: str) -> str:
    rows = "".join(
        f"<tr><td>{html.escape(c['condition'])}</td><td>{html.escape(c['domain_order'])}</td>"
        f"<td>{c['test_set']}</td><td>{c['occupied']}</td><td>{c['completed']}</td></tr>"
        for c in p["cells"])
    status = ", ".join(f"{html.escape(k)}: {v}" for k, v in sorted(p["status"].items()))
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>Progress</title>"
            f"<link rel='stylesheet' href='/static/style.css'></head><body class='researcher'>"
            f"<h1>{html.escape(title)}: progress</h1><p>Study version {p['study_version']}. "
            f"Sessions by status: {status or 'none'}; previews (not counted): {p['previews']}; "
            f"in progress on older study versions: {p['older_versions_in_progress']}.</p>"
            f"<table><thead><tr><th>condition</th><th>domain order</th><th>test set</th>"
            f"<th>occupied (completed + active)</th><th>completed</th></tr></thead>"
            f"<tbody>{rows}</tbody></table></body></html>")
