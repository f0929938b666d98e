"""The `closed_loop` page of `StudyService`: answers checked in full before anything else,
decisions made by `decisions.Decider` outside every request's transaction, and recorded in a
short transaction of their own by whichever request (or server process) sees them first.

The page's view while the next item is being decided is ``{"kind": "closed_loop",
"preparing": true, "retry_ms": ...}`` with no ``item`` (docs/study.md, "Preparing the next
item"); ``GET /api/state?wait=S`` waits up to S seconds for it.
"""

from __future__ import annotations

import logging
from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from cfteach.mdp.scoring import is_optimal

from . import schemas
from .decisions import result_or_none
from .errors import ApiError
from .feedback import feedback_for
from .games import ScoringError, public_game, replay
from .layout import instance_layout
from .live import path_states, responses_of
from .models import ClosedLoopItem, Event, Session, aware, utcnow
from .queries import PENDING_ITEM

#: Where a transaction keeps the item on screen (`_cl_pending`), in its session's `info`.
PENDING_KEY = "cfteach.pending_item"

if TYPE_CHECKING:
    from .decisions import Decider
    from .live import LiveTeaching

log = logging.getLogger(__name__)

#: How soon the page should ask again while an item is being prepared (ms).
RETRY_MS = 250
#: Longest wait a `GET /api/state?wait=` may ask for (s).
MAX_WAIT_S = 5.0


class ClosedLoopSteps:
    """Mixed into `StudyService` (which provides Session, ReadSession, live, decider, ...)."""

    if TYPE_CHECKING:  # what StudyService provides (the sessionmaker `Session` too)
        live: LiveTeaching
        decider: Decider
        _pg: bool
        _studies: dict[str, dict]

        def study_of(self, row: Session) -> dict: ...
        def steps(self, row: Session) -> list[dict]: ...
        def _advance(self, db: DBSession, row: Session, now: datetime) -> None: ...
        def _demo_completions(self, db: DBSession, row: Session, step_index: int,
                              n: int) -> list[int]: ...

    # -- reading ---------------------------------------------------------------------------
    def _cl_stored(self, db: DBSession, row: Session, step_index: int) -> list[dict]:
        return list(db.scalars(select(Event.payload).where(
            Event.session_pk == row.id, Event.step_index == step_index,
            Event.type == "item_done").order_by(Event.seq)))

    def _cl_pending(self, db: DBSession, row: Session, step: dict) -> ClosedLoopItem | None:
        """The item on screen: the first one without an answer.

        Looked up once per transaction (an event's checks, its page and the decision that
        page waits for each ask): on PostgreSQL every lookup is a round trip, and round trips,
        not CPU, made most of an event's time (docs/study.md, "Load"). An answer recorded in
        the transaction forgets it (`_cl_item_done`)."""
        key = (PENDING_KEY, row.id, step["domain"])
        if key not in db.info:
            db.info[key] = db.scalar(PENDING_ITEM, {"pk": row.id, "domain": step["domain"]})
        return db.info[key]

    def _cl_item(self, db: DBSession, row: Session, domain: str,
                 position: int | None) -> ClosedLoopItem | None:
        if position is None:
            return None
        return db.scalar(select(ClosedLoopItem).where(
            ClosedLoopItem.session_pk == row.id, ClosedLoopItem.domain == domain,
            ClosedLoopItem.position == position))

    def _cl_play_actions(self, db: DBSession, row: Session, step: dict,
                         item: ClosedLoopItem) -> int:
        """Steps a demonstration or feedback replay lasts (feedback plays the right answer
        and the participant's side by side: the longer of the two)."""
        study = self.study_of(row)
        n = len(self.live.pool(study, step["domain"]).ds.action_names(item.demo))
        if item.kind == "feedback":
            failed = self._cl_item(db, row, step["domain"], item.about)
            n = max(n, len((failed.actions or "").split()) if failed else 0)
        return n

    # -- answering -------------------------------------------------------------------------
    def _cl_check_answer(self, db: DBSession, row: Session, step: dict,
                         p: schemas.ItemDone) -> tuple[ClosedLoopItem, dict[str, Any]]:
        """Check the answer to the item on screen in full, before anything is written (no
        teacher work and no write at all: a refused answer costs a lookup or two and, for a
        test, one replay of its moves). Returns the item and what to record on it
        (`_cl_item_done`); the next item is decided after the commit (`_cl_ensure`)."""
        item = self._cl_pending(db, row, step)
        if item is None or p.item != item.position:
            shown = "none: the next is being prepared" if item is None else item.position
            raise ApiError(409, "wrong_item", f"item {p.item} is not the item on screen "
                           f"({shown})")
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
            return item, {"actions": " ".join(p.actions), "reward": score.reward,
                          "optimal_reward": best,
                          "optimal": is_optimal(score.reward, best)}
        if p.actions is not None:
            raise ApiError(422, "bad_payload", f"item_done: a {item.kind} takes no actions")
        # demonstrations and feedback alike: played and watched to the end, on the
        # server's clock, before the teacher may count them as seen
        done = self._demo_completions(db, row, row.step_index, item.position + 1)
        if done[item.position] < 1:
            what = "demonstration" if item.kind == "demonstration" else "feedback replay"
            raise ApiError(409, "demos_unwatched", f"the {what} must be played and "
                           "watched to the end at least once")
        return item, {}

    @staticmethod
    def _cl_item_done(db: DBSession, item: ClosedLoopItem, answer: dict[str, Any],
                      now: datetime) -> None:
        """Record a checked answer (`_cl_check_answer`) on its item; the item on screen is
        then the next one."""
        db.info.pop((PENDING_KEY, item.session_pk, item.domain), None)
        for name, value in answer.items():
            setattr(item, name, value)
        item.done_at = now
        item.server_ms = max(0, int((now - aware(item.shown_at)).total_seconds() * 1000))

    # -- deciding and recording --------------------------------------------------------------
    def _cl_job(self, db: DBSession, row: Session, step: dict) -> dict | None:
        """What to decide for a closed-loop page with no item on screen (None if it has one)."""
        if row.status != "in_progress" or self._cl_pending(db, row, step) is not None:
            return None
        return {"pk": row.id, "seed": row.seed, "version": row.study_version,
                "domain": step["domain"], "step_index": row.step_index,
                "responses": responses_of(self._cl_stored(db, row, row.step_index)),
                "served": [[k, d] for k, d in db.execute(
                    select(ClosedLoopItem.kind, ClosedLoopItem.demo).where(
                        ClosedLoopItem.session_pk == row.id,
                        ClosedLoopItem.domain == step["domain"])
                    .order_by(ClosedLoopItem.position))]}

    def _cl_ensure(self, job: dict, wait: float) -> bool:
        """Submit the decision `job` names (once) and record it if it is ready within
        `wait` s; True if recorded (by us or by anyone else)."""
        study = self._studies[job["version"]]
        fut = self.decider.submit(study, job["pk"], job["seed"], job["domain"],
                                  job["responses"], job.get("served"))
        done, result = result_or_none(fut, wait)
        if not done:
            self.decider.heal(fut)
            return False
        return self._cl_record(job, result)

    def _cl_record(self, job: dict, result: dict | None) -> bool:
        """Store the decided item (or, when teaching is over, move the session on) if the
        session is still where the decision was asked; exactly once across processes (the
        session row lock, and the unique item position)."""
        # StudyService's sessionmaker; a class-level annotation would shadow the model name
        with self.Session() as db:  # type: ignore[attr-defined]
            try:
                with db.begin():
                    q = select(Session).where(Session.id == job["pk"])
                    row = db.scalar(q.with_for_update() if self._pg else q)
                    if (row is None or row.status != "in_progress"
                            or row.step_index != job["step_index"]):
                        return True
                    step = self.steps(row)[row.step_index]
                    if self._cl_pending(db, row, step) is not None:
                        return True
                    n = db.scalar(select(func.count()).select_from(Event).where(
                        Event.session_pk == row.id, Event.step_index == row.step_index,
                        Event.type == "item_done"))
                    if n != len(job["responses"]):
                        return False  # answered since: a newer decision is needed
                    now = utcnow()
                    if result is not None and "mismatch" in result:
                        # never decide from answers to items the participant did not see:
                        # this domain's teaching ends here, loudly (docs/study.md)
                        log.error("closed_loop session %s, %s: %s; its teaching phase "
                                  "ends here", row.participant_id, job["domain"],
                                  result["mismatch"])
                        result = None
                    if result is None:
                        self._advance(db, row, now)
                        return True
                    if result["index"] != n:
                        raise ApiError(500, "teacher_mismatch", "the teacher's item "
                                       f"{result['index']} does not follow {n} answers")
                    db.add(self._cl_row(row, job["domain"], result, now))
                    db.info.pop((PENDING_KEY, row.id, job["domain"]), None)
            except IntegrityError:
                return True  # another request or server process recorded it first
        return True

    def _cl_row(self, row: Session, domain: str, r: dict, now: datetime) -> ClosedLoopItem:
        study = self.study_of(row)
        ds = self.live.pool(study, domain).ds
        inst = ds.instance(r["demo"])
        return ClosedLoopItem(
            session_pk=row.id, domain=domain, position=r["index"], kind=r["kind"],
            purpose=r["purpose"], demo=r["demo"], about=r["about"],
            env_code="".join(str(int(b)) for b in inst.env_code), env_index=int(inst.index),
            start_state=inst.state_to_json(ds.trajectory_states(r["demo"])[0]),
            shown_at=now, expected_area=r["expected_area"],
            predicted_optimal=r.get("predicted_optimal"),
            predicted_held_out=r.get("predicted_held_out"), progress=r.get("progress"))

    # -- the page --------------------------------------------------------------------------
    def _cl_view(self, db: DBSession, row: Session, step: dict) -> dict:
        """What the page shows for the item on screen, or that it is being prepared."""
        study = self.study_of(row)
        dom = step["domain"]
        item = self._cl_pending(db, row, step)
        if item is None:
            return {"preparing": True, "retry_ms": RETRY_MS}
        ds = self.live.pool(study, dom).ds
        inst = ds.instance(item.demo)
        layout = instance_layout(dom, inst)
        optimal = [inst.state_to_json(x) for x in ds.trajectory_states(item.demo)]
        out: dict[str, Any] = {"preparing": False, "progress": item.progress,
                               "item": {"position": item.position, "kind": item.kind,
                                        "purpose": item.purpose, "layout": layout}}
        if item.kind == "test":
            out["item"].update(game=public_game(self.live.game(study, dom, item.demo)),
                               elapsed_ms=max(0, int((utcnow() - aware(item.shown_at))
                                                     .total_seconds() * 1000)))
            return out
        completed = self._demo_completions(db, row, row.step_index,
                                           item.position + 1)[item.position]
        if item.kind == "demonstration":
            out["item"].update(states=optimal, n_actions=len(optimal) - 1,
                               completed=completed)
        else:
            failed = self._cl_item(db, row, dom, item.about)
            game = self.live.game(study, dom, item.demo)
            answer = (failed.actions or "").split() if failed else []
            out["item"].update(optimal=optimal, answer=path_states(game, answer),
                               n_actions=max(len(optimal), len(answer) + 1) - 1,
                               completed=completed,
                               explain=feedback_for(study, dom, game, answer,
                                                    ds.action_names(item.demo)))
        return out
