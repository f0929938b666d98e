"""`cfteach study export`: tidy CSVs for the analysis (format agreed in docs/study.md)."""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import sessionmaker

from .db import make_engine
from .live import teacher_seed
from .models import ClientReport, ClosedLoopItem, Event, Session, TestResponse, aware

# closed_loop's lessons are counterfactual demonstrations, without feature scaffolding
COUNTERFACTUAL = {"counterfactual_only", "proposed", "closed_loop"}
FEATURE = {"feature_only", "proposed"}

COLUMNS: dict[str, list[tuple[str, str, str]]] = {
    "participants.csv": [
        ("participant_id", "str", "opaque random id of the session (not the Prolific ID)"),
        ("prolific_pid", "str", "Prolific participant id (PROLIFIC_PID); empty for previews"),
        ("study_id", "str", "Prolific STUDY_ID"),
        ("session_id", "str", "Prolific SESSION_ID"),
        ("condition", "str", "baseline | feature_only | counterfactual_only | proposed | "
                             "closed_loop"),
        ("counterfactual", "0/1", "1 if the condition uses counterfactual scaffolding"),
        ("feature_scaffolding", "0/1", "1 if the condition uses feature scaffolding"),
        ("domain_order", "str", "domains in the order shown, joined by ';'"),
        ("test_set", "int", "which of the alternative test sets (0-based)"),
        ("status", "str", "completed | screened_out | declined (said no to consent) | "
                          "abandoned | in_progress"),
        ("is_preview", "0/1", "1 for preview/test sessions (not counted in assignment)"),
        ("started_at", "ISO 8601 UTC", "session creation time"),
        ("completed_at", "ISO 8601 UTC", "completion (or screen-out) time; empty otherwise"),
        ("practice_attempts", "int", "attempts used on the qualifying practice game"),
        ("age", "int", "self-reported age"),
        ("gender", "str", "self-reported gender"),
        ("education", "str", "self-reported education (optional item)"),
        ("study_version", "str", "content hash of the study file the session ran on"),
    ],
    "test_responses.csv": [
        ("participant_id", "str", "see participants.csv"),
        ("condition", "str", "see participants.csv"),
        ("domain", "str", "domain of the test"),
        ("domain_position", "int", "1..3: position of the domain in the participant's order"),
        ("test_id", "str", "test identifier, unique within the study"),
        ("difficulty", "str", "low | medium | high"),
        ("overlap", "float", "the test's belief overlap (difficulty = 1 / overlap)"),
        ("trial_index", "int", "1..6: order in which the test was shown within the domain"),
        ("actions", "str", "the participant's actions, space-separated"),
        ("n_actions", "int", "number of actions"),
        ("reward", "float", "w* . feature counts of the participant's trajectory (server replay)"),
        ("optimal_reward", "float", "reward of the robot's optimal answer"),
        ("optimal", "0/1", "1 if reward equals optimal_reward within 1e-9 (the paper's M1)"),
        ("optimal_length", "int", "number of actions of the robot's optimal answer"),
        ("time_ms", "int", "from the test being first shown to its submission, on the server's "
                           "clock (from the previous page's answer being stored to this "
                           "answer arriving; a reload keeps counting)"),
        ("client_time_ms", "int", "the same time as the browser reported it (not trusted)"),
        ("confidence", "int", "1..5: confidence item (1 = Not Confident)"),
    ],
    "likert.csv": [
        ("participant_id", "str", "see participants.csv"),
        ("condition", "str", "see participants.csv"),
        ("domain", "str", "domain whose demonstrations are rated"),
        ("domain_position", "int", "1..3"),
        ("item", "str", "informativeness | mental_effort"),
        ("value", "int", "1..5 (1 = Not Informative / No Effort)"),
    ],
    "demo_views.csv": [
        ("participant_id", "str", "see participants.csv"),
        ("condition", "str", "see participants.csv"),
        ("domain", "str", "domain of the demonstration"),
        ("demo_index", "int", "0-based position of the demonstration in the curriculum "
                              "(closed_loop: the item's position, see closed_loop_items.csv)"),
        ("plays_completed", "int", "plays the server saw run from start to end for at least "
                                   "the replay's length"),
        ("replays", "int", "plays started beyond the first"),
        ("watch_ms", "int", "total time spent playing this demonstration, on the server's "
                            "clock (from each play's start to its end)"),
        ("client_watch_ms", "int", "the same total as the browser reported it (not trusted)"),
    ],
    "comments.csv": [
        ("participant_id", "str", "see participants.csv"),
        ("condition", "str", "see participants.csv"),
        ("source", "str", "survey (comment box under a domain's Likert items) | demographics "
                          "(final comments)"),
        ("domain", "str", "domain of the survey; empty for demographics"),
        ("comment", "str", "free text as typed: MAY IDENTIFY THE PARTICIPANT (names, "
                           "places, contacts); review before sharing"),
    ],
    "closed_loop_items.csv": [
        ("participant_id", "str", "see participants.csv (closed_loop participants only)"),
        ("domain", "str", "domain being taught"),
        ("domain_position", "int", "1..3: position of the domain in the participant's order"),
        ("position", "int", "0-based position of the item in the domain's teaching phase"),
        ("kind", "str", "demonstration | test (diagnostic) | feedback"),
        ("purpose", "str", "lesson | remedial (demonstration), diagnostic (test), feedback"),
        ("about", "int", "diagnostic test: the lesson's position; feedback and remedial "
                         "lesson: the failed test's position"),
        ("env_code", "str", "the item's instance (its env code bits)"),
        ("env_index", "int", "the item's instance index in the domain"),
        ("start_state", "JSON", "the item's start state"),
        ("teacher_seed", "int", "seed of the participant's teacher in this domain "
                                "(ClosedLoopTeacher.replay rebuilds the session from it)"),
        ("actions", "str", "test: the participant's actions, space-separated"),
        ("reward", "float", "test: w* . feature counts of the answer (server replay)"),
        ("optimal_reward", "float", "test: reward of the robot's optimal answer"),
        ("regret", "float", "test: optimal_reward - reward (0 when optimal)"),
        ("optimal", "0/1", "test: 1 if reward equals optimal_reward within 1e-9"),
        ("expected_area", "float", "the teacher's belief when the item was chosen (feedback: "
                                   "before the failed answer's update): expected area of "
                                   "the learner's posterior (sr)"),
        ("predicted_optimal", "float", "test: the belief's P(optimal answer) to this test"),
        ("predicted_held_out", "float", "the belief's mean P(optimal) on the post-teaching "
                                        "tests when the item was chosen"),
        ("time_ms", "int", "from the item being decided to its answer, on the server's clock"),
        ("shown_at", "ISO 8601 UTC", "when the item was decided (the previous answer stored)"),
        ("done_at", "ISO 8601 UTC", "when its answer was stored; empty if never answered"),
    ],
    "client_reports.csv": [
        ("participant_id", "str", "see participants.csv; empty if the page had no valid "
                                  "session"),
        ("reported_at", "ISO 8601 UTC", "when the server stored the report"),
        ("path", "str", "the refused request (/api/event, /api/session, /api/state)"),
        ("http_status", "int", "the server's (or a proxy's) HTTP status"),
        ("error", "str", "the server's error code (e.g. bad_moves, wrong_step)"),
        ("detail", "str", "the server's message (never shown to the participant)"),
        ("event_type", "str", "type of the refused event, if it was one"),
        ("step_index", "int", "step the refused event was sent for"),
        ("event", "JSON", "the refused event exactly as the page sent it"),
    ],
}


def _iso(dt: datetime | None) -> str:
    if dt is None:
        return ""
    return aware(dt).astimezone(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _b(x: bool) -> int:
    return 1 if x else 0


def export_csv(db_url: str, out: str | Path, *, include_previews: bool = False,
               abandon_after_minutes: float = 120.0) -> dict[str, int]:
    """Write the tidy CSVs plus `data_dictionary.csv`; returns rows written per file."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    engine = make_engine(db_url)
    now = datetime.now(UTC)
    rows: dict[str, list[list]] = {name: [] for name in COLUMNS}
    with sessionmaker(engine)() as db:
        q = select(Session).order_by(Session.id)
        if not include_previews:
            q = q.where(Session.is_preview.is_(False))
        sessions = db.scalars(q).all()
        by_pk = {s.id: s for s in sessions}
        s: Session | None  # below: the session of each row, None if left out
        for s in sessions:
            status = s.status
            idle = (now - aware(s.last_active_at)).total_seconds()
            if status == "in_progress" and idle > abandon_after_minutes * 60:
                status = "abandoned"
            rows["participants.csv"].append([
                s.participant_id, s.prolific_pid or "", s.study_id or "", s.session_id or "",
                s.condition, _b(s.condition in COUNTERFACTUAL), _b(s.condition in FEATURE),
                s.domain_order, s.test_set, status, _b(s.is_preview), _iso(s.created_at),
                _iso(s.completed_at), s.practice_attempts,
                "" if s.age is None else s.age, s.gender or "", s.education or "",
                s.study_version])
        for t in db.scalars(select(TestResponse).order_by(TestResponse.session_pk,
                                                          TestResponse.id)):
            s = by_pk.get(t.session_pk)
            if s is None:
                continue
            rows["test_responses.csv"].append([
                s.participant_id, s.condition, t.domain, t.domain_position, t.test_id,
                t.difficulty, "" if t.overlap is None else repr(t.overlap), t.trial_index,
                t.actions, t.n_actions, repr(t.reward), repr(t.optimal_reward), _b(t.optimal),
                t.optimal_length, t.server_ms, t.time_ms, t.confidence])
        views: dict[tuple, list[int]] = defaultdict(lambda: [0, 0, 0, 0])
        for ev in db.scalars(select(Event).where(Event.type.in_(
                ("likert", "demo_play_start", "demo_play_end", "demographics")))
                .order_by(Event.session_pk, Event.seq)):
            s = by_pk.get(ev.session_pk)
            if s is None:
                continue
            order = s.domain_order.split(";")
            if ev.type == "likert":
                dom = ev.domain
                for item in ("informativeness", "mental_effort"):
                    rows["likert.csv"].append([s.participant_id, s.condition, dom,
                                               order.index(dom or "") + 1, item,
                                               ev.payload[item]])
                if ev.payload.get("comment"):
                    rows["comments.csv"].append([s.participant_id, s.condition, "survey", dom,
                                                 ev.payload["comment"]])
            elif ev.type == "demographics":
                if ev.payload.get("comments"):
                    rows["comments.csv"].append([s.participant_id, s.condition, "demographics",
                                                 "", ev.payload["comments"]])
            elif ev.type in ("demo_play_start", "demo_play_end"):
                dom = ev.domain
                v = views[(s.id, dom, ev.payload["demo_index"])]
                if ev.type == "demo_play_start":
                    v[1] += 1
                else:
                    v[0] += int(bool(ev.verified))
                    v[2] += ev.server_ms or 0
                    v[3] += int(ev.payload["watch_ms"])
        for (pk, dom, k), (done, starts, ms, client_ms) in sorted(views.items()):
            s = by_pk[pk]
            rows["demo_views.csv"].append([s.participant_id, s.condition, dom, k, done,
                                           max(0, starts - 1), ms, client_ms])
        for it in db.scalars(select(ClosedLoopItem).order_by(
                ClosedLoopItem.session_pk, ClosedLoopItem.domain, ClosedLoopItem.position)):
            s = by_pk.get(it.session_pk)
            if s is None:
                continue
            test = it.kind == "test" and it.reward is not None
            regret = (repr(max(0.0, it.optimal_reward - it.reward))
                      if test and it.optimal_reward is not None and it.reward is not None
                      else "")
            rows["closed_loop_items.csv"].append([
                s.participant_id, it.domain, s.domain_order.split(";").index(it.domain) + 1,
                it.position, it.kind, it.purpose, "" if it.about is None else it.about,
                it.env_code, it.env_index, strict_json(it.start_state),
                teacher_seed(s.seed, it.domain), it.actions or "",
                repr(it.reward) if test else "", repr(it.optimal_reward) if test else "",
                regret,
                _b(bool(it.optimal)) if test else "", repr(it.expected_area),
                "" if it.predicted_optimal is None else repr(it.predicted_optimal),
                "" if it.predicted_held_out is None else repr(it.predicted_held_out),
                "" if it.server_ms is None else it.server_ms, _iso(it.shown_at),
                _iso(it.done_at)])
        for r in db.scalars(select(ClientReport).order_by(ClientReport.id)):
            s = by_pk.get(r.session_pk) if r.session_pk is not None else None
            if r.session_pk is not None and s is None:
                continue  # a preview's report (or one of a session left out)
            sent = r.event if isinstance(r.event, dict) else {}
            rows["client_reports.csv"].append([
                s.participant_id if s else "", _iso(r.server_at), r.path, r.http_status,
                r.error, r.detail, sent.get("type", ""), sent.get("step_index", ""),
                "" if r.event is None else strict_json(r.event)])
    counts = {}
    for name, cols in COLUMNS.items():
        with open(out / name, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow([c for c, _, _ in cols])
            w.writerows([_finite_cells(r) for r in rows[name]])
        counts[name] = len(rows[name])
    with open(out / "data_dictionary.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["file", "column", "type", "description"])
        for name, cols in COLUMNS.items():
            for c, kind, d in cols:
                w.writerow([name, c, kind, d])
    engine.dispose()
    return counts


def _strict(x: object) -> object:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _strict(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_strict(v) for v in x]
    return x


def strict_json(x: object) -> str:
    """JSON for a CSV cell: never NaN or Infinity (stored before the server refused them,
    they become null), which strict JSON readers reject."""
    return json.dumps(_strict(x), sort_keys=True, allow_nan=False)


def _finite_cells(row: list) -> list:
    """A CSV row with non-finite numbers left empty (as missing values are)."""
    return ["" if isinstance(c, float) and not math.isfinite(c) else c for c in row]
