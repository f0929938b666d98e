"""The FastAPI app: participant page + JSON API, researcher progress page."""

from __future__ import annotations

import hmac
import html
import secrets
from pathlib import Path

from fastapi import FastAPI, Header, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.middleware.base import BaseHTTPMiddleware

from . import schemas
from .config import StudyError, load_study
from .db import make_engine, upgrade
from .ratelimit import RateLimiter
from .service import ApiError, StudyService
from .versions import store_version, unstored_in_progress

HERE = Path(__file__).parent
MAX_BODY = 64 * 1024
CSP = ("default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
       "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'self'")


class _Limits(BaseHTTPMiddleware):
    """Body size cap and security headers on every response."""

    async def dispatch(self, request: Request, call_next):  # noqa: ANN001, ANN201
        if request.method in ("POST", "PUT", "PATCH"):
            ctype = request.headers.get("content-type", "")
            if request.url.path.startswith("/api/") and not ctype.startswith("application/json"):
                return _err(415, "json_only", "send the body as application/json")
            declared = request.headers.get("content-length")
            if declared is not None and (not declared.isdigit() or int(declared) > MAX_BODY):
                return _err(413, "too_large", f"request body over {MAX_BODY} bytes")
            body = await request.body()
            if len(body) > MAX_BODY:
                return _err(413, "too_large", f"request body over {MAX_BODY} bytes")
        response = await call_next(request)
        response.headers["Content-Security-Policy"] = CSP
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Referrer-Policy"] = "no-referrer"
        response.headers["Cache-Control"] = "no-store"
        return response


def _err(status: int, code: str, message: str) -> JSONResponse:
    return JSONResponse({"error": code, "detail": message}, status_code=status)


def create_app(study_dir: str | Path, db_url: str | None = None, *,
               researcher_token: str | None = None, seed: int | None = None,
               sessions_per_minute: int = 120, events_per_minute: int = 600,
               new_version: bool = False) -> FastAPI:
    """Build the server for one study folder; migrations run here, before serving.

    Rate limits (0 = off): new sessions per client address, events per session, per minute.
    The study file is kept in the database, so sessions started on an older file finish on
    it. Sessions in progress on a file the database does not hold (a database from before
    files were kept) would be stranded: refuse to start unless `new_version`.
    """
    study = load_study(study_dir)
    if db_url is None:
        db_url = f"sqlite:///{Path(study_dir) / 'study.db'}"
    engine = make_engine(db_url)
    upgrade(engine)
    stranded = unstored_in_progress(engine, study["version"])
    if stranded and not new_version:
        engine.dispose()
        which = ", ".join(f"{n} on version {v}" for v, n in sorted(stranded.items()))
        raise StudyError(f"{sum(stranded.values())} session(s) are in progress on a study file "
                         f"this database does not hold ({which}); serve that file until they "
                         "finish, or pass --new-version to start anyway (they cannot finish)")
    store_version(engine, study)
    service = StudyService(engine, study, seed=seed)
    token = researcher_token or secrets.token_urlsafe(16)
    session_limit = RateLimiter(sessions_per_minute)
    event_limit = RateLimiter(events_per_minute)

    app = FastAPI(title="cfteach study", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.service = service
    app.state.researcher_token = token
    app.add_middleware(_Limits)
    app.mount("/static", StaticFiles(directory=HERE / "static"), name="static")
    page = (HERE / "templates" / "index.html").read_text()

    @app.exception_handler(ApiError)
    async def _api_error(_req: Request, e: ApiError) -> JSONResponse:
        return _err(e.status, e.code, e.message)

    @app.exception_handler(RequestValidationError)
    async def _bad_request(_req: Request, e: RequestValidationError) -> JSONResponse:
        err = e.errors()[0] if e.errors() else {"loc": (), "msg": "invalid request"}
        loc = ".".join(str(x) for x in err.get("loc", ()))
        return _err(422, "bad_request", f"{loc}: {err.get('msg')}")

    @app.get("/favicon.ico")
    def favicon() -> Response:
        return Response(status_code=204)

    @app.get("/", response_class=HTMLResponse)
    def index() -> HTMLResponse:
        return HTMLResponse(page.replace("{{title}}", html.escape(study["title"])))

    @app.post("/api/session")
    def start(req: schemas.SessionRequest, request: Request) -> JSONResponse:
        addr = request.client.host if request.client else "?"
        if not session_limit.allow(addr):
            raise ApiError(429, "rate_limited", "too many new sessions; try again in a minute")
        row, resumed = service.start(req)
        return JSONResponse({"token": row.token, "resumed": resumed,
                             "participant_id": row.participant_id})

    @app.get("/api/state")
    def state(x_session_token: str | None = Header(default=None)) -> JSONResponse:
        return JSONResponse(service.state(x_session_token))

    @app.post("/api/event")
    def event(req: schemas.EventRequest, request: Request,
              x_session_token: str | None = Header(default=None)) -> JSONResponse:
        if not event_limit.allow(x_session_token or "?"):
            raise ApiError(429, "rate_limited", "too many events; slow down")
        return JSONResponse(service.post_event(x_session_token, req))

    def _check_researcher(given: str | None) -> None:
        if not given or not hmac.compare_digest(given, token):
            raise ApiError(403, "forbidden", "researcher token required")

    @app.get("/api/researcher/progress")
    def progress(x_researcher_token: str | None = Header(default=None)) -> dict:
        _check_researcher(x_researcher_token)
        return service.progress()

    @app.get("/researcher", response_class=HTMLResponse)
    def researcher(token: str | None = None) -> HTMLResponse:
        _check_researcher(token)
        return HTMLResponse(_progress_html(service.progress(), study["title"]))

    return app


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
