"""Study logic independent of HTTP: sessions, assignment, events, scoring, step advance."""

from __future__ import annotations

import hmac
import random
import re
import secrets
import threading
from datetime import datetime
from typing import Any

from pydantic import ValidationError
from sqlalchemy import Engine, func, select, text
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession
from sqlalchemy.orm import sessionmaker

from cfteach.domains.spec import BUILTIN_ACTIONS
from cfteach.mdp.scoring import is_optimal

from . import schemas
from .assignment import all_cells, cell_counts, choose_cell, completed_counts
from .build import browser_game
from .controls import PRACTICE_CONTROLS, controls
from .feedback import feedback_for
from .games import ScoringError, public_game, replay
from .layout import instance_layout
from .live import LiveTeaching, path_states, responses_of
from .models import ClientReport, ClosedLoopItem, Event, Session, TestResponse, aware, utcnow
from .steps import ALLOWED, build_steps, demo_required_ms
from .texts import EDUCATION, GENDERS, LIKERT, design_facts
from .versions import load_version

_PLACEHOLDER = re.compile(r"^\{\{?%.*%\}?\}$|^$")
_ID_OK = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
TOKEN_BYTES = 32
TOKEN_RE = re.compile(schemas.TOKEN_PATTERN)  # secrets.token_urlsafe(TOKEN_BYTES)
ELSEWHERE = ("This study is already in progress in another browser. Please continue it "
             "there (the browser and tab you started it in).")


def well_formed_token(token: str | None) -> bool:
    """Whether `token` could be a session token at all (checked before any lookup)."""
    return token is not None and TOKEN_RE.fullmatch(token) is not None


class ApiError(Exception):
    """A request the server refuses; `status` is the HTTP code, `code` a stable name."""

    def __init__(self, status: int, code: str, message: str) -> None:
        super().__init__(message)
        self.status, self.code, self.message = status, code, message


class StudyService:
    """All participant-facing operations; one instance per running server."""

    def __init__(self, engine: Engine, study: dict, *, seed: int | None = None) -> None:
        self.engine = engine
        self.study = study
        self.Session = sessionmaker(engine, expire_on_commit=False)
        self.ReadSession = sessionmaker(engine.execution_options(readonly=True),
                                        expire_on_commit=False)
        self._lock = threading.Lock()
        self._rng = random.Random(seed)
        self._pg = engine.dialect.name == "postgresql"
        self._steps_cache: dict[tuple, list[dict]] = {}
        self._cache_lock = threading.Lock()
        # Study versions by id: the current one plus older ones that still have sessions,
        # read from the database on first use (see versions.py).
        self._studies: dict[str, dict] = {study["version"]: study}
        self.live = LiveTeaching()

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
        pid_key = f"{study_id or ''}:{pid}" if pid and not preview else None
        with self._lock, self.Session() as db, db.begin():
            if self._pg:
                db.execute(text("SELECT pg_advisory_xact_lock(727274)"))
            if pid_key:
                row = db.scalar(select(Session).where(Session.pid_key == pid_key))
                if row is not None:
                    if _proves(row, req.token, sess_id):
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
        q = select(Session).where(Session.token == token)
        if lock and self._pg:
            q = q.with_for_update()
        row = db.scalar(q)
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

    def state(self, token: str | None) -> dict:
        with self.ReadSession() as db, db.begin():
            row = self._session(db, token)
            return self._view(db, row)

    def _view(self, db: DBSession, row: Session) -> dict:
        steps = self.steps(row)
        s = self.study_of(row)
        comp = s["completion"]
        base = {"status": row.status, "step_index": row.step_index, "n_steps": len(steps),
                "participant_id": row.participant_id, "is_preview": row.is_preview,
                "design": design_facts(s)}
        if row.status in ("screened_out", "declined"):
            return {**base, "step": {"kind": row.status, "code": _code(comp, row.status),
                                     "redirect": _redirect(comp, row.status, row)}}
        step = dict(steps[row.step_index])
        kind = step["kind"]
        if kind == "consent" and s.get("consent_html"):
            step["html"] = s["consent_html"]
        if kind in ("free_play", "practice"):
            p = s["practice"]
            step.update(layout=p["layout"], game=p["game"],  # not secret: energy shown
                        weights=p["weights"], start_energy=p["start_energy"],
                        target_energy=p["target_energy"], attempts_used=row.practice_attempts,
                        attempts_allowed=s["practice_attempts"], controls=PRACTICE_CONTROLS)
        elif kind == "domain_intro":
            step["info"] = _public_info(s["domain_info"][step["domain"]])
            # A few configurations of this game: the demonstrations' layouts, unplayed.
            seen, examples = set(), []
            if row.condition == "closed_loop":
                examples = s["closed_loop"][step["domain"]]["examples"]
            for d in s["curricula"][step["domain"]].get(row.condition, []):
                key = repr(d["layout"])
                if key not in seen and len(examples) < 3:
                    seen.add(key)
                    examples.append({"layout": d["layout"], "state": d["states"][0]})
            step["examples"] = examples
        elif kind == "demos":
            demos = s["curricula"][step["domain"]][row.condition]
            step.update(info=_public_info(s["domain_info"][step["domain"]]), demos=demos,
                        step_ms=s["demo_step_ms"],
                        completed=self._demo_completions(db, row, row.step_index, len(demos)))
        elif kind == "closed_loop":
            step.update(info=_public_info(s["domain_info"][step["domain"]]),
                        step_ms=s["demo_step_ms"], **self._cl_view(db, row, step))
        elif kind == "survey":
            step["items"] = {k: LIKERT[k] for k in ("informativeness", "mental_effort")}
        elif kind == "test":
            t = s["tests"][step["domain"]][row.test_set][step.pop("test_index")]
            step.update(browser_game(t), info=_public_info(s["domain_info"][step["domain"]]),
                        confidence=LIKERT["confidence"],
                        n_trials=len(s["tests"][step["domain"]][row.test_set]),
                        # so time_ms counts from the first showing, even across reloads
                        elapsed_ms=max(0, int((utcnow() - aware(row.step_entered_at))
                                              .total_seconds() * 1000)))
        elif kind == "feedback":
            n = db.scalar(select(func.count()).select_from(TestResponse).where(
                TestResponse.session_pk == row.id, TestResponse.domain == step["domain"],
                TestResponse.optimal.is_(True)))
            total = len(s["tests"][step["domain"]][row.test_set])
            step.update(correct=int(n or 0), total=total)
        elif kind == "demographics":
            step.update(genders=GENDERS, education=EDUCATION)
        elif kind == "complete":
            step.update(code=comp["completed"],
                        redirect=None if row.is_preview else _redirect(comp, "completed", row))
        return {**base, "step": step}

    def _demo_completions(self, db: DBSession, row: Session, step_index: int,
                          n: int) -> list[int]:
        """Plays of each demonstration the server saw run start to end (`verified`)."""
        counts = [0] * n
        for payload in db.scalars(select(Event.payload).where(
                Event.session_pk == row.id, Event.step_index == step_index,
                Event.type == "demo_play_end", Event.verified.is_(True))):
            if 0 <= payload["demo_index"] < n:
                counts[payload["demo_index"]] += 1
        return counts

    def _check_demo(self, db: DBSession, row: Session, step: dict, ev: Event,
                    p: schemas.DemoPlayStart | schemas.DemoPlayEnd, now: datetime) -> None:
        """Refuse unknown demonstrations; time a play's end against its start, server-side.

        A play counts as watched only if this end closes a start of the same demonstration
        (the last play event of the step) and lasted, on the server's clock, at least the
        replay's length minus a small tolerance (`steps.demo_required_ms`).
        """
        study = self.study_of(row)
        if step["kind"] == "closed_loop":
            item = self._cl_pending(db, row, step)
            if item is None or p.demo_index != item.position or item.kind == "test":
                raise ApiError(422, "unknown_demo", f"demo_index {p.demo_index} is not the "
                               "demonstration this page shows")
            pool = self.live.pool(study, step["domain"])
            demos = {p.demo_index: {"actions": pool.ds.action_names(item.demo)}}
        else:
            demos = study["curricula"][step["domain"]][row.condition]
        if p.demo_index >= len(demos) and step["kind"] != "closed_loop":
            raise ApiError(422, "unknown_demo", f"demo_index {p.demo_index} is not one of this "
                           f"page's {len(demos)} demonstrations")
        if not isinstance(p, schemas.DemoPlayEnd):
            return
        start = db.scalar(select(Event).where(
            Event.session_pk == row.id, Event.step_index == row.step_index,
            Event.type.in_(("demo_play_start", "demo_play_end")))
            .order_by(Event.seq.desc()).limit(1))
        if (start is None or start.type != "demo_play_start"
                or start.payload["demo_index"] != p.demo_index):
            ev.server_ms, ev.verified = None, False
            return
        ev.server_ms = max(0, int((now - aware(start.server_at)).total_seconds() * 1000))
        need = demo_required_ms(len(demos[p.demo_index]["actions"]), study["demo_step_ms"])
        ev.verified = bool(p.completed) and ev.server_ms >= need

    # -- events ---------------------------------------------------------------------------

    def post_event(self, token: str | None, req: schemas.EventRequest) -> dict:
        """Store one event exactly once and apply its effect on the step machine."""
        try:
            self._cl_prepare(token, req)
        except (ApiError, ValueError, KeyError, TypeError, RuntimeError):
            pass  # the transaction below refuses the event with the right answer
        with self.Session() as db:
            try:
                with db.begin():
                    row, result = self._apply(db, token, req)
                    db.flush()
                    view = self._view(db, row)
            except IntegrityError as e:
                raise ApiError(409, "duplicate_event",
                               f"event {req.event_id} was already stored") from e
            # Only now, after the commit, is the event acknowledged.
            return {"ok": True, **result, "state": view}

    def _apply(self, db: DBSession, token: str | None,
               req: schemas.EventRequest) -> tuple[Session, dict]:
        row = self._session(db, token, lock=True)
        dup = db.scalar(select(Event.id).where(Event.session_pk == row.id,
                                               Event.event_id == req.event_id))
        if dup is not None:
            raise ApiError(409, "duplicate_event", f"event {req.event_id} was already stored")
        if row.status != "in_progress":
            raise ApiError(409, "session_finished", f"this session is {row.status}")
        if req.step_index != row.step_index:
            raise ApiError(409, "wrong_step", f"event is for step {req.step_index} but the "
                           f"session is at step {row.step_index}")
        steps = self.steps(row)
        study = self.study_of(row)
        step = steps[row.step_index]
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
        now = utcnow()
        row.event_seq += 1
        ev = Event(session_pk=row.id, seq=row.event_seq, event_id=req.event_id,
                   step_index=row.step_index, step_kind=kind, domain=step.get("domain"),
                   type=req.type,
                   payload=payload.model_dump(), client_ms=req.client_ms, server_at=now)
        if req.type in ("demo_play_start", "demo_play_end"):
            self._check_demo(db, row, step, ev, payload, now)
        db.add(ev)
        db.flush()
        row.last_active_at = now
        result: dict[str, Any] = {}
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
            result = self._practice(row, payload)
            advance = result["passed"]
        elif req.type == "test_response":
            result = self._score_test(db, row, step, ev, payload, now)
            advance = True
        elif req.type == "demographics":
            row.age, row.gender, row.education = payload.age, payload.gender, payload.education
            advance = True
        elif req.type == "item_done":
            advance = self._cl_item_done(db, row, step, ev, payload, now)
        while advance:
            row.step_index += 1
            row.step_entered_at = now
            advance = False
            if steps[row.step_index]["kind"] == "complete":
                row.status = "completed"
                row.completed_at = now
            elif steps[row.step_index]["kind"] == "closed_loop":
                # the first item is decided now; a teacher with nothing to teach skips ahead
                advance = self._cl_decide(db, row, steps[row.step_index], now) is None
        return row, result

    # -- the closed_loop condition (cfteach.study.live) ----------------------------------

    def _cl_stored(self, db: DBSession, row: Session, step_index: int) -> list[dict]:
        return list(db.scalars(select(Event.payload).where(
            Event.session_pk == row.id, Event.step_index == step_index,
            Event.type == "item_done").order_by(Event.seq)))

    def _cl_pending(self, db: DBSession, row: Session, step: dict) -> ClosedLoopItem | None:
        """The item on screen: the first one without an answer."""
        return db.scalar(select(ClosedLoopItem).where(
            ClosedLoopItem.session_pk == row.id, ClosedLoopItem.domain == step["domain"],
            ClosedLoopItem.done_at.is_(None)).order_by(ClosedLoopItem.position).limit(1))

    def _cl_decide(self, db: DBSession, row: Session, step: dict,
                   now: datetime) -> ClosedLoopItem | None:
        """Decide the next item from the stored events and record it; None when done."""
        study = self.study_of(row)
        dom = step["domain"]
        responses = responses_of(self._cl_stored(db, row, row.step_index))
        # usually found ready (decided by `_cl_prepare` or in the background), as this
        # runs inside the write transaction
        item, summary = self.live.decide(study, row.id, row.seed, dom, responses, ahead=False)
        if item is None:
            return None
        ds = self.live.pool(study, dom).ds
        inst = ds.instance(item.demo)
        rec = ClosedLoopItem(
            session_pk=row.id, domain=dom, position=item.index, kind=item.kind,
            purpose=item.purpose, demo=item.demo, about=item.about,
            env_code="".join(str(int(b)) for b in inst.env_code), env_index=int(inst.index),
            start_state=inst.state_to_json(ds.trajectory_states(item.demo)[0]),
            shown_at=now, **summary)
        db.add(rec)
        return rec

    def _cl_prepare(self, token: str | None, req: schemas.EventRequest) -> None:
        """Before the write transaction: decide the item this event will lead to, so the
        transaction (which holds SQLite's write lock) only finds it ready. Speculative: any
        problem is left for the transaction to report, and a refused event's decision is
        simply never used (teachers are found by the responses they have seen)."""
        if req.type not in ("item_done", "continue"):
            return
        with self.ReadSession() as db, db.begin():
            row = self._session(db, token)
            if row.status != "in_progress" or req.step_index != row.step_index:
                return
            steps = self.steps(row)
            step = steps[row.step_index]
            if step["kind"] == "closed_loop" and req.type == "item_done":
                pending = self._cl_pending(db, row, step)
                p = req.payload
                if pending is None or p.get("item") != pending.position or (
                        pending.kind == "test") != (p.get("actions") is not None):
                    return
                payloads = [*self._cl_stored(db, row, row.step_index), p]
            elif (req.type == "continue" and row.step_index + 1 < len(steps)
                  and steps[row.step_index + 1]["kind"] == "closed_loop"):
                step, payloads = steps[row.step_index + 1], []
            else:
                return
            study, pk, seed = self.study_of(row), row.id, row.seed
        self.live.decide(study, pk, seed, step["domain"], responses_of(payloads))

    def _cl_item_done(self, db: DBSession, row: Session, step: dict, ev: Event,
                      p: schemas.ItemDone, now: datetime) -> bool:
        """Record the answer to the item on screen and decide the next; True when the
        domain's teaching is over (the session moves on to the survey)."""
        item = self._cl_pending(db, row, step)
        if item is None or p.item != item.position:
            raise ApiError(409, "wrong_item", f"item {p.item} is not the item on screen "
                           f"({'none' if item is None else item.position})")
        study = self.study_of(row)
        if item.kind == "test":
            if p.actions is None:
                raise ApiError(422, "bad_payload", "item_done: a test needs its actions")
            game = self.live.game(study, step["domain"], item.demo)
            try:
                score = replay(game, study["domain_info"][step["domain"]]["weights"],
                               p.actions)
            except ScoringError as e:
                raise ApiError(422, "bad_moves", str(e)) from e
            best = float(self.live.pool(study, step["domain"]).ds.reward(item.demo))
            item.actions, item.reward, item.optimal_reward = " ".join(p.actions), \
                score.reward, best
            item.optimal = is_optimal(score.reward, best)
        else:
            if p.actions is not None:
                raise ApiError(422, "bad_payload", f"item_done: a {item.kind} takes no actions")
            if item.kind == "demonstration":
                done = self._demo_completions(db, row, row.step_index, item.position + 1)
                if done[item.position] < 1:
                    raise ApiError(409, "demos_unwatched", "the demonstration must be played "
                                   "and watched to the end at least once")
        item.done_at = now
        item.server_ms = max(0, int((now - aware(item.shown_at)).total_seconds() * 1000))
        db.flush()  # the event is stored: the teacher now sees its response
        return self._cl_decide(db, row, step, now) is None

    def _cl_view(self, db: DBSession, row: Session, step: dict) -> dict:
        """What the page shows for the item on screen (decided when the last answer came)."""
        study = self.study_of(row)
        dom = step["domain"]
        item = self._cl_pending(db, row, step)
        if item is None:  # cannot happen: the step is left when teaching ends
            raise ApiError(409, "wrong_step", "no closed-loop item is pending")
        pool = self.live.pool(study, dom)
        ds = pool.ds
        inst = ds.instance(item.demo)
        layout = instance_layout(dom, inst)
        optimal = [inst.state_to_json(x) for x in ds.trajectory_states(item.demo)]
        out: dict[str, Any] = {"item": {"position": item.position, "kind": item.kind,
                                        "purpose": item.purpose, "layout": layout}}
        if item.kind == "demonstration":
            out["item"].update(states=optimal, n_actions=len(optimal) - 1,
                               completed=self._demo_completions(
                                   db, row, row.step_index, item.position + 1)[item.position])
        elif item.kind == "test":
            out["item"].update(game=public_game(self.live.game(study, dom, item.demo)),
                               elapsed_ms=max(0, int((utcnow() - aware(item.shown_at))
                                                     .total_seconds() * 1000)))
        else:
            failed = db.scalar(select(ClosedLoopItem).where(
                ClosedLoopItem.session_pk == row.id, ClosedLoopItem.domain == dom,
                ClosedLoopItem.position == item.about))
            game = self.live.game(study, dom, item.demo)
            answer = (failed.actions or "").split()
            out["item"].update(optimal=optimal, answer=path_states(game, answer),
                               explain=feedback_for(study, dom, game, answer,
                                                    ds.action_names(item.demo)))
        return out

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


def _public_info(info: dict) -> dict:
    out = {k: info[k] for k in ("title", "task", "actions", "note", "keys", "effects_word")}
    # Study files written before per-domain controls play the built-in actions' keys.
    out["controls"] = info.get("controls") or controls(BUILTIN_ACTIONS.values(), info["keys"])
    return out


#: The no-consent code of study files written before `--no-consent-code` existed.
DEFAULT_DECLINED_CODE = "NOCONSENT"


def _code(comp: dict, which: str) -> str:
    if which == "declined":
        return comp.get("declined", DEFAULT_DECLINED_CODE)
    return comp[which]


def _redirect(comp: dict, which: str, row: Session) -> str | None:
    if not comp.get("url") or row.is_preview:
        return None
    return f"{comp['url']}{_code(comp, which)}"


def _first_error(e: ValidationError) -> str:
    err = e.errors()[0]
    loc = ".".join(str(x) for x in err["loc"]) or "body"
    return f"{loc}: {err['msg']}"
