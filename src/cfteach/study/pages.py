"""What each page shows (`StudyService._view`) and the server's timing of demonstration
plays: the read side of the step machine, mixed into `StudyService`."""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING

from sqlalchemy import func, select
from sqlalchemy.orm import Session as DBSession

from cfteach.domains.spec import BUILTIN_ACTIONS

from . import schemas
from .controls import PRACTICE_CONTROLS, controls
from .errors import ApiError
from .games import public_game
from .models import Event, Session, TestResponse, aware, utcnow
from .page_json import static_game
from .queries import VERIFIED_PLAY_ENDS
from .steps import demo_required_ms
from .texts import EDUCATION, GENDERS, LIKERT, design_facts

if TYPE_CHECKING:
    from .models import ClosedLoopItem


class PageViews:
    """Mixed into `StudyService` (which provides study_of, steps, live, _cl_* ...)."""

    if TYPE_CHECKING:  # what StudyService and ClosedLoopSteps provide
        def study_of(self, row: Session) -> dict: ...
        def steps(self, row: Session) -> list[dict]: ...
        def _cl_view(self, db: DBSession, row: Session, step: dict) -> dict: ...
        def _cl_pending(self, db: DBSession, row: Session,
                        step: dict) -> ClosedLoopItem | None: ...
        def _cl_play_actions(self, db: DBSession, row: Session, step: dict,
                             item: ClosedLoopItem) -> int: ...

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
            step.update(layout=p["layout"],  # the whole game: not secret, energy is shown
                        game=static_game(p["game"], dict),
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
            step.update(layout=t["layout"], game=static_game(t["game"], public_game),
                        info=_public_info(s["domain_info"][step["domain"]]),
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
        for payload in db.scalars(VERIFIED_PLAY_ENDS,
                                  {"pk": row.id, "step_index": step_index}):
            if 0 <= payload["demo_index"] < n:
                counts[payload["demo_index"]] += 1
        return counts

    def _play_length(self, db: DBSession, row: Session, step: dict,
                     p: schemas.DemoPlayStart | schemas.DemoPlayEnd) -> int:
        """Refuse a play of a demonstration this page does not show; the steps it lasts."""
        if step["kind"] == "closed_loop":
            item = self._cl_pending(db, row, step)
            if item is None or p.demo_index != item.position or item.kind == "test":
                raise ApiError(422, "unknown_demo", f"demo_index {p.demo_index} is not the "
                               "demonstration or feedback this page shows")
            return self._cl_play_actions(db, row, step, item)
        demos = self.study_of(row)["curricula"][step["domain"]][row.condition]
        if p.demo_index >= len(demos):
            raise ApiError(422, "unknown_demo", f"demo_index {p.demo_index} is not one of this "
                           f"page's {len(demos)} demonstrations")
        return len(demos[p.demo_index]["actions"])

    def _time_play(self, db: DBSession, row: Session, ev: Event,
                   p: schemas.DemoPlayStart | schemas.DemoPlayEnd, n_actions: int,
                   now: datetime) -> dict:
        """Time a play's end against its start, server-side.

        A play counts as watched only if this end closes a start of the same demonstration
        (the last play event of the step) and lasted, on the server's clock, at least the
        replay's length minus a small tolerance (`steps.demo_required_ms`).
        """
        if not isinstance(p, schemas.DemoPlayEnd):
            return {}
        need = demo_required_ms(n_actions, self.study_of(row)["demo_step_ms"])
        start = db.scalar(select(Event).where(
            Event.session_pk == row.id, Event.step_index == row.step_index,
            Event.type.in_(("demo_play_start", "demo_play_end")))
            .order_by(Event.seq.desc()).limit(1))
        if (start is None or start.type != "demo_play_start"
                or start.payload["demo_index"] != p.demo_index):
            ev.server_ms, ev.verified = None, False
            return _play(ev, need, "no_start")
        ev.server_ms = max(0, int((now - aware(start.server_at)).total_seconds() * 1000))
        ev.verified = bool(p.completed) and ev.server_ms >= need
        why = None if ev.verified else "not_completed" if not p.completed else "too_short"
        return _play(ev, need, why)


def _play(ev: Event, need: int, why: str | None) -> dict:
    """How the server judged a play (in the demo_play_end acknowledgement): the page can
    tell a play its own network fault shortened (`no_start`, `too_short` after a refused or
    late start) from a skipped one, and replay it instead of blaming the participant. An
    unverified play never takes away an earlier verified one."""
    return {"play": {"verified": bool(ev.verified), "server_ms": ev.server_ms,
                     "required_ms": need, "reason": why}}


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
