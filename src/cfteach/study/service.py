"""Study logic independent of HTTP: sessions, assignment, events, scoring, step advance."""

from __future__ import annotations

import hmac
import random
import re
import secrets
import threading
from datetime import datetime
from typing import Any, NamedTuple, TypeGuard, cast

from pydantic import ValidationError
from sqlalchemy import Engine, func, select, text
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession
from sqlalchemy.orm import sessionmaker
from starlette.concurrency import run_in_threadpool

from cfteach.mdp.scoring import is_optimal

from . import schemas
from .assignment import all_cells, cell_counts, choose_cell, completed_counts
from .closed_loop_steps import MAX_WAIT_S, ClosedLoopSteps
from .db import durable_barrier
from .decisions import Decider, result_or_none_async
from .errors import ApiError
from .games import ScoringError, replay
from .identity import find_participant, participant_key, study_key
from .live import LiveTeaching
from .models import ClientReport, ClosedLoopItem, Event, Session, TestResponse, aware, utcnow
from .pages import PageViews
from .queries import EVENT_BY_ID, SESSION_BY_TOKEN, SESSION_BY_TOKEN_LOCKED
from .steps import ALLOWED, build_steps
from .versions import load_version

_PLACEHOLDER = re.compile(r"^\{\{?%.*%\}?\}$|^$")
_ID_OK = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
TOKEN_BYTES = 32
TOKEN_RE = re.compile(schemas.TOKEN_PATTERN)  # secrets.token_urlsafe(TOKEN_BYTES)
ELSEWHERE = ("This study is already in progress in another browser. Please continue it "
             "there (the browser and tab you started it in).")


def well_formed_token(token: str | None) -> TypeGuard[str]:
    """Whether `token` could be a session token at all (checked before any lookup)."""
    return token is not None and TOKEN_RE.fullmatch(token) is not None




class CheckedEvent(NamedTuple):
    """An event `_check_event` accepted, with what its checks found."""

    kind: str  # the kind of page it was sent on
    step: dict
    payload: Any  # its payload, validated (the schemas.PAYLOADS model of its type)
    answer: tuple[ClosedLoopItem, dict[str, Any]] | None  # a closed-loop answer's record
    play_length: int  # a play's steps (demo_play_start, demo_play_end)


#: Sessions over: a returning participant gets the page for the status, never a new session.
FINISHED = ("completed", "screened_out", "declined")


class StudyService(PageViews, ClosedLoopSteps):
    """All participant-facing operations; one instance per running server."""

    def __init__(self, engine: Engine, study: dict, *, seed: int | None = None,
                 decision_workers: int = 0, event_wait_s: float = 0.1) -> None:
        self.engine = engine
        self.study = study
        self.Session = sessionmaker(engine, expire_on_commit=False)
        self.ReadSession = sessionmaker(engine.execution_options(readonly=True),
                                        expire_on_commit=False)
        self._rng = random.Random(seed)
        self._pg = engine.dialect.name == "postgresql"
        self._steps_cache: dict[tuple, list[dict]] = {}
        self._cache_lock = threading.Lock()
        # Study versions by id: the current one plus older ones that still have sessions,
        # read from the database on first use (see versions.py).
        self._studies: dict[str, dict] = {study["version"]: study}
        self.live = LiveTeaching()
        # closed-loop decisions: worker processes (0: one thread of this process)
        self.decider = Decider(self.live, [study], decision_workers)
        self.event_wait_s = event_wait_s

    def close(self) -> None:
        self.decider.close()

    # -- sessions -------------------------------------------------------------------------

    def start(self, req: schemas.SessionRequest) -> tuple[Session, bool]:
        """Resume the participant's session or assign one.

        A Prolific PID that already has a session resumes it only with proof: the session's
        token (stored by the browser that started it) or the Prolific SESSION_ID it started
        with. Knowing a PID alone gets 409 `session_elsewhere` and changes nothing.
        """
        pid = req.prolific_pid
        for name, value in (("PROLIFIC_PID", pid), ("STUDY_ID", req.study_id),
                            ("SESSION_ID", req.session_id)):
            if value is not None and not _PLACEHOLDER.match(value) and not _ID_OK.match(value):
                raise ApiError(422, "bad_parameter",
                               f"{name} may contain only letters, digits, '_' and '-'")
        placeholder = pid is None or bool(_PLACEHOLDER.match(pid))
        preview = placeholder or req.mode in ("test", "preview")
        pid = None if placeholder else pid
        study_id = None if req.study_id and _PLACEHOLDER.match(req.study_id) else req.study_id
        sess_id = None if req.session_id and _PLACEHOLDER.match(req.session_id) else req.session_id
        # one session per Prolific participant and study: keyed on the study's own identity
        # (fixed at `study init`), never on the STUDY_ID the link carries
        pid_key = participant_key(study_key(self.study), pid) if pid and not preview else None
        # Assignments (and so the draws from self._rng) take turns on the database's own
        # lock: SQLite's write lock, taken at BEGIN (db.py), or PostgreSQL's advisory
        # lock. No lock of this process is held through the commit, so concurrent starts
        # share their fsyncs (sqlite_writes): under 200 arrivals in 2 s, a process lock
        # held through each commit's fsync made new sessions wait up to 3.5 s.
        with self.Session() as db, db.begin():
            if self._pg:
                db.execute(text("SELECT pg_advisory_xact_lock(727274)"))
            if pid_key and pid:  # (a key only ever comes with its PID)
                row = find_participant(db, pid_key, pid)
                if row is not None:
                    # a finished session shows its status page (screened out, declined,
                    # completed: nothing left to do or to steal in it), to anyone
                    if row.status in FINISHED or _proves(row, req.token, sess_id):
                        return row, True
                    raise ApiError(409, "session_elsewhere", ELSEWHERE)
            elif req.token:
                row = db.scalar(select(Session).where(Session.token == req.token))
                if row is not None and row.is_preview and row.prolific_pid == pid:
                    return row, True
            now = utcnow()
            cond, order, test_set = choose_cell(db, self.study, now, self._rng)
            row = Session(
                participant_id=secrets.token_hex(8), token=secrets.token_urlsafe(TOKEN_BYTES),
                study_version=self.study["version"], pid_key=pid_key, prolific_pid=pid,
                study_id=study_id, session_id=sess_id, condition=cond,
                domain_order=";".join(order), test_set=test_set,
                seed=self._rng.randrange(2**31), status="in_progress", is_preview=preview,
                step_index=0, event_seq=0, practice_attempts=0, created_at=now,
                last_active_at=now, step_entered_at=now)
            db.add(row)
        return row, False

    def _session(self, db: DBSession, token: str | None, *, lock: bool = False) -> Session:
        if not well_formed_token(token):
            raise ApiError(401, "no_session", "missing or malformed session token")
        q = SESSION_BY_TOKEN_LOCKED if lock and self._pg else SESSION_BY_TOKEN
        row = db.scalar(q, {"token": token})
        if row is None:
            raise ApiError(401, "no_session", "unknown session token")
        if row.study_version not in self._studies:
            old = load_version(db, row.study_version)
            if old is None:
                raise ApiError(410, "study_changed",
                               "this session belongs to a study version the server no longer has")
            with self._cache_lock:
                self._studies[row.study_version] = old
        return row

    def study_of(self, row: Session) -> dict:
        """The study version `row` started on (loaded by `_session`)."""
        return self._studies[row.study_version]

    def steps(self, row: Session) -> list[dict]:
        key = (row.study_version, row.domain_order, row.test_set, row.seed, row.condition)
        steps = self._steps_cache.get(key)
        if steps is None:
            steps = build_steps(self.study_of(row), row.domain_order.split(";"), row.test_set,
                                row.seed, row.condition)
            with self._cache_lock:
                if len(self._steps_cache) >= 2048:  # bounded: recent sessions only
                    self._steps_cache.pop(next(iter(self._steps_cache)))
                self._steps_cache[key] = steps
        return steps

    # -- reading the current page ---------------------------------------------------------

    def state(self, token: str | None, wait: float = 0.0) -> dict:
        """The page to show. Only what is durable is shown (`durable_barrier`). A
        closed-loop page whose next item is not decided yet submits the decision (once)
        and waits for it up to `wait` s (then answers ``preparing: true``)."""
        return self._settle(token, *self.read_state(token), wait)

    def _settle(self, token: str | None, view: dict, job: dict | None, wait: float) -> dict:
        """`view` (with its pending decision `job`), or, once the decision is recorded
        within `wait` s, the page read again with the item."""
        wait = min(max(0.0, wait), MAX_WAIT_S)
        for _ in range(3):
            if job is None or not self._cl_ensure(job, wait):
                return view
            wait = 0.0  # recorded: read the page once more, with what was recorded
            view, job = self.read_state(token)
        return view

    async def state_async(self, token: str | None, wait: float = 0.0) -> dict:
        """`state` for the event loop: the reads and writes run in the thread pool, and
        the wait for a decision holds no thread at all."""
        view, job = await run_in_threadpool(self.read_state, token)
        return await self._settle_async(token, view, job, wait)

    async def _settle_async(self, token: str | None, view: dict, job: dict | None,
                            wait: float) -> dict:
        wait = min(max(0.0, wait), MAX_WAIT_S)
        for _ in range(3):
            if job is None:
                return view
            fut = self.decider.submit(self._studies[job["version"]], job["pk"],
                                      job["seed"], job["domain"], job["responses"],
                                      job.get("served"))
            done, result = await result_or_none_async(fut, wait)
            if not done:
                if fut.done():
                    self.decider.heal(fut)
                return view
            if not await run_in_threadpool(self._cl_record, job, result):
                return view
            wait = 0.0
            view, job = await run_in_threadpool(self.read_state, token)
        return view

    def read_state(self, token: str | None) -> tuple[dict, dict | None]:
        """The page as stored (and durable), and the decision it waits for, if any."""
        durable_barrier(self.engine)
        with self.ReadSession() as db, db.begin():
            row = self._session(db, token)
            return self._page(db, row)

    def _page(self, db: DBSession, row: Session) -> tuple[dict, dict | None]:
        view = self._view(db, row)
        job = None
        if view["step"].get("preparing"):
            job = self._cl_job(db, row, self.steps(row)[row.step_index])
        return view, job

    # -- events ---------------------------------------------------------------------------

    def post_event(self, token: str | None, req: schemas.EventRequest) -> dict:
        """Store one event exactly once and apply its effect on the step machine."""
        result, view, job = self.store_event(token, req)
        return {"ok": True, **result,
                "state": self._settle(token, view, job, self.event_wait_s)}

    async def post_event_async(self, token: str | None, req: schemas.EventRequest) -> dict:
        result, view, job = await run_in_threadpool(self.store_event, token, req)
        state = await self._settle_async(token, view, job, self.event_wait_s)
        return {"ok": True, **result, "state": state}

    def store_event(self, token: str | None,
                    req: schemas.EventRequest) -> tuple[dict, dict, dict | None]:
        """Store the event (durably); return what its acknowledgement adds, and the page it
        leads to (with the decision that page waits for, if any).

        The page is read in the event's own transaction, just before its commit: it is
        exactly what the commit makes durable, and the request needs no second
        transaction (and no second session lookup) to read it (docs/study.md, "Load")."""
        try:
            with self.Session() as db, db.begin():
                row, result = self._apply(db, token, req)
                db.flush()
                view, job = self._page(db, row)
        except IntegrityError as e:
            durable_barrier(self.engine)  # the stored copy is durable before we say so
            raise ApiError(409, "duplicate_event",
                           f"event {req.event_id} was already stored") from e
        except ApiError as e:
            if e.code == "duplicate_event":
                durable_barrier(self.engine)
            raise
        # Only now, after the (durable) commit, is the event acknowledged; a closed-loop
        # answer waits a moment for the next item (usually decided ahead) before
        # answering "preparing".
        return result, view, job

    def _apply(self, db: DBSession, token: str | None,
               req: schemas.EventRequest) -> tuple[Session, dict]:
        row = self._session(db, token, lock=True)
        try:
            checked = self._check_event(db, row, req)
        except ApiError as e:
            # A copy of a stored event is refused as what it is, whatever else is wrong
            # with it now (its step passed, its item answered). Looked up only here: an
            # accepted copy is caught by the events' unique id at its insert (store_event),
            # which saves every event a round trip to the database (docs/study.md, "Load").
            if db.scalar(EVENT_BY_ID, {"pk": row.id, "event_id": req.event_id}) is not None:
                raise ApiError(409, "duplicate_event",
                               f"event {req.event_id} was already stored") from e
            raise
        return row, self._store(db, row, req, checked)

    def _check_event(self, db: DBSession, row: Session,
                     req: schemas.EventRequest) -> CheckedEvent:
        """Refuse the event (ApiError) before anything is written: the session's state, the
        step, the payload, the demonstration a play is of, and a closed-loop answer, checked
        in full."""
        if row.status != "in_progress":
            raise ApiError(409, "session_finished", f"this session is {row.status}")
        if req.step_index != row.step_index:
            raise ApiError(409, "wrong_step", f"event is for step {req.step_index} but the "
                           f"session is at step {row.step_index}")
        step = self.steps(row)[row.step_index]
        kind = step["kind"]
        if req.type != "page_load" and req.type not in ALLOWED[kind]:
            raise ApiError(422, "wrong_event_type",
                           f"event type {req.type!r} is not accepted on a {kind} page")
        model = schemas.PAYLOADS.get(req.type)
        if model is None:
            raise ApiError(422, "wrong_event_type", f"unknown event type {req.type!r}")
        try:
            payload = model.model_validate(req.payload)
        except ValidationError as e:
            raise ApiError(422, "bad_payload", f"{req.type}: {_first_error(e)}") from e
        answer, play_length = None, 0
        if req.type == "item_done":
            answer = self._cl_check_answer(db, row, step, cast(schemas.ItemDone, payload))
        elif req.type in ("demo_play_start", "demo_play_end"):
            play_length = self._play_length(
                db, row, step, cast(schemas.DemoPlayStart | schemas.DemoPlayEnd, payload))
        return CheckedEvent(kind, step, payload, answer, play_length)

    def _store(self, db: DBSession, row: Session, req: schemas.EventRequest,
               checked: CheckedEvent) -> dict:
        """Write a checked event and apply its effect on the step machine."""
        kind, step, payload, answer = checked.kind, checked.step, checked.payload, checked.answer
        study = self.study_of(row)
        now = utcnow()
        row.event_seq += 1
        row.last_active_at = now  # with event_seq: one UPDATE of the session, not two
        ev = Event(session_pk=row.id, seq=row.event_seq, event_id=req.event_id,
                   step_index=row.step_index, step_kind=kind, domain=step.get("domain"),
                   type=req.type,
                   payload=payload.model_dump(), client_ms=req.client_ms, server_at=now)
        result: dict[str, Any] = {}
        if req.type in ("demo_play_start", "demo_play_end"):
            result = self._time_play(db, row, ev, cast(schemas.DemoPlayStart | schemas.DemoPlayEnd,
                                                       payload), checked.play_length, now)
        db.add(ev)
        db.flush()  # a copy of a stored event fails here (unique id)
        advance = False
        if req.type in ("continue", "consent", "likert"):
            advance = True
            if kind == "demos":
                n = len(study["curricula"][step["domain"]][row.condition])
                done = self._demo_completions(db, row, row.step_index, n)
                if min(done) < 1:
                    missing = ", ".join(str(k + 1) for k, d in enumerate(done) if d < 1)
                    raise ApiError(409, "demos_unwatched", "every demonstration must be "
                                   "played and watched to the end at least once; not yet: "
                                   f"demonstration {missing}")
        elif req.type == "decline":
            row.status = "declined"  # final: frees the assignment cell at once
            row.completed_at = now
        elif req.type == "practice_attempt":
            result = self._practice(row, cast(schemas.PracticeAttempt, payload))
            advance = result["passed"]
        elif req.type == "test_response":
            result = self._score_test(db, row, step, ev, cast(schemas.TestAnswer, payload), now)
            advance = True
        elif req.type == "demographics":
            who = cast(schemas.Demographics, payload)
            row.age, row.gender, row.education = who.age, who.gender, who.education
            advance = True
        elif answer is not None:
            self._cl_item_done(db, *answer, now)
        if advance:
            self._advance(db, row, now)
        return result

    def _advance(self, db: DBSession, row: Session, now: datetime) -> None:
        """Move to the next page (a closed-loop page's first item is decided after the
        commit, outside the transaction: see closed_loop_steps)."""
        row.step_index += 1
        row.step_entered_at = now
        if self.steps(row)[row.step_index]["kind"] == "complete":
            row.status = "completed"
            row.completed_at = now

    def _practice(self, row: Session, p: schemas.PracticeAttempt) -> dict:
        prac = self.study_of(row)["practice"]
        try:
            score = replay(prac["game"], prac["weights"], p.actions, require_end=False)
        except ScoringError as e:
            raise ApiError(422, "bad_moves", str(e)) from e
        energy = prac["start_energy"] + score.reward
        passed = score.finished and is_optimal(energy, prac["target_energy"])
        row.practice_attempts += 1
        if not passed and row.practice_attempts >= self.study_of(row)["practice_attempts"]:
            row.status = "screened_out"
            row.completed_at = utcnow()
        return {"passed": passed, "energy": energy, "target_energy": prac["target_energy"],
                "finished": score.finished, "attempts_used": row.practice_attempts}

    def _score_test(self, db: DBSession, row: Session, step: dict, ev: Event,
                    p: schemas.TestAnswer, now: datetime) -> dict:
        dom = step["domain"]
        study = self.study_of(row)
        t = study["tests"][dom][row.test_set][step["test_index"]]
        try:
            score = replay(t["game"], study["domain_info"][dom]["weights"], p.actions)
        except ScoringError as e:
            raise ApiError(422, "bad_moves", str(e)) from e
        entered = aware(row.step_entered_at)
        db.add(TestResponse(
            session_pk=row.id, event_pk=ev.id, domain=dom, domain_position=step["position"],
            test_id=t["test_id"], difficulty=t["difficulty"], overlap=t["overlap"],
            trial_index=step["trial"], actions=" ".join(p.actions), n_actions=len(p.actions),
            reward=score.reward, optimal_reward=t["optimal_reward"],
            optimal=is_optimal(score.reward, t["optimal_reward"]),
            optimal_length=t["optimal_length"], time_ms=p.time_ms,
            server_ms=int((now - entered).total_seconds() * 1000), confidence=p.confidence))
        return {}

    # -- problems reported by the page ----------------------------------------------------

    def report(self, token: str | None, req: schemas.ClientReport) -> dict:
        """Store a refused request the page reports (once per report id).

        Accepted with any token, or none: the session may be the very thing that failed.
        """
        with self.Session() as db:
            try:
                with db.begin():
                    pk = None
                    if token and len(token) <= 64:
                        pk = db.scalar(select(Session.id).where(Session.token == token))
                    db.add(ClientReport(
                        report_id=req.report_id, session_pk=pk, path=req.path,
                        http_status=req.http_status, error=req.error, detail=req.detail,
                        event=req.event, client_ms=req.client_ms, server_at=utcnow()))
            except IntegrityError:
                return {"ok": True, "duplicate": True}
        return {"ok": True}

    # -- researcher -----------------------------------------------------------------------

    def progress(self) -> dict:
        with self.ReadSession() as db, db.begin():
            now = utcnow()
            counts = cell_counts(db, self.study, now)
            done = completed_counts(db, self.study)
            status = dict(db.execute(select(Session.status, func.count()).where(
                Session.study_version == self.study["version"], Session.is_preview.is_(False))
                .group_by(Session.status)).all())
            previews = db.scalar(select(func.count()).select_from(Session).where(
                Session.is_preview.is_(True))) or 0
            older = db.scalar(select(func.count()).select_from(Session).where(
                Session.study_version != self.study["version"], Session.is_preview.is_(False),
                Session.status == "in_progress")) or 0
        cells = [{"condition": c, "domain_order": ";".join(o), "test_set": t,
                  "occupied": counts[(c, o, t)], "completed": done[(c, o, t)]}
                 for (c, o, t) in all_cells(self.study)]
        return {"study_version": self.study["version"], "status": status,
                "previews": previews, "older_versions_in_progress": older, "cells": cells}


def _proves(row: Session, token: str | None, session_id: str | None) -> bool:
    """Whether the request shows it comes from whoever started `row` (constant-time)."""
    if token and hmac.compare_digest(token.encode(), row.token.encode()):
        return True
    return bool(session_id and row.session_id
                and hmac.compare_digest(session_id.encode(), row.session_id.encode()))


def _first_error(e: ValidationError) -> str:
    err = e.errors()[0]
    loc = ".".join(str(x) for x in err["loc"]) or "body"
    return f"{loc}: {err['msg']}"
