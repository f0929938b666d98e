"""The live `closed_loop` condition: a `ClosedLoopTeacher` per participant and domain.

The teacher's state is a pure function of (pool, settings, seed, responses), and the
responses are the participant's stored `item_done` events. So nothing here is the only copy
of anything: the pools are derived from the study file (rebuilt at server start, cached per
server), and a teacher is cached only as a shortcut, found by the responses it has seen
(its event count and content). After a restart, or when the cache does not match the
database, the teacher is replayed from the events (`ClosedLoopTeacher.replay`).

Decisions run in the decision workers (`decisions.Decider`), one `LiveTeaching` per
worker; deciding ahead (the item after a demonstration or feedback) is the Decider's job.
"""

from __future__ import annotations

import json
import threading
import zlib
from collections import OrderedDict
from typing import Any

from cfteach.closedloop import ClosedLoopTeacher, LessonPool, TeacherSettings, build_pool
from cfteach.closedloop.teacher import Item
from cfteach.jsonable import to_jsonable

#: Sessions whose teachers are kept per server (up to two teachers of a few hundred kB
#: each); older ones are replayed from their events when needed.
MAX_TEACHERS = 512
#: Diagnostic-test tables kept per server (up to about half a MB each in Python objects).
MAX_GAMES = 256


def teacher_seed(session_seed: int, domain: str) -> int:
    """The teacher's seed for one participant and domain (stable across restarts)."""
    return zlib.crc32(f"{session_seed}:{domain}".encode()) & 0x7FFFFFFF


def settings_of(cell: dict) -> TeacherSettings:
    s = dict(cell["settings"])
    s["zpd_band"] = tuple(s["zpd_band"])
    # A study file written before the confusion term runs its sessions without it, so
    # their replays (and so their next items) stay those they were served.
    s.setdefault("confused", (0.0,))
    # ... and one written before the probes were drawn as the post-tests are, or before
    # answers were weighed by what was taught since, keeps what it was written with.
    s.setdefault("probes", "prior")
    s.setdefault("confusion", "grid")
    return TeacherSettings(**s)


def pool_from_cell(cell: dict) -> LessonPool:
    """Rebuild a domain's lesson pool from its `closed_loop` cell in study.json (a study
    made before the backbone existed has none: its teacher behaves as it did then)."""
    p = cell["pool"]
    return build_pool(cell["domain"], profile=p["profile"], human_models=p["human_models"],
                      seed=p["seed"], held_out=list(cell["held_out"]),
                      backbone=list(cell.get("backbone") or ()))


class ReplayMismatch(ValueError):
    """A teacher rebuilt from a session's answers would have served other items than the
    ones stored (the code or its numerics changed under a running study): its next item
    would be decided from answers to items the participant never saw."""


def check_served(t: ClosedLoopTeacher, served: list[list]) -> None:
    """Raise `ReplayMismatch` unless `t` served exactly `served` (``[kind, demo]`` per
    answered item, in order, as stored)."""
    got = [[it.kind, int(it.demo)] for it in t.items]
    want = [[str(k), int(d)] for k, d in served]
    if got != want:
        at = next((k for k, (g, w) in enumerate(zip(got, want, strict=False)) if g != w),
                  min(len(got), len(want)))
        g = got[at] if at < len(got) else None
        w = want[at] if at < len(want) else None
        raise ReplayMismatch(f"item {at}: the teacher rebuilt from the answers serves {g}, "
                             f"but {w} was stored")


def replay_export(cell: dict, rows: list[dict[str, str]]) -> ClosedLoopTeacher:
    """Rebuild one participant's teacher in one domain offline from the study file's
    `closed_loop` cell and their rows of `closed_loop_items.csv` (in position order), and
    check it served those items (kind, purpose, instance, start state): `ReplayMismatch`
    names the first that differs, e.g. when this cfteach is not the one that ran the
    study, instead of a teacher silently rebuilt from answers to other items."""
    pool = pool_from_cell(cell)
    responses = [{"actions": r["actions"].split()} if r["kind"] == "test" else {}
                 for r in rows]
    t = ClosedLoopTeacher.replay(pool, responses, settings=settings_of(cell),
                                 seed=int(rows[0]["teacher_seed"]) if rows else 0)
    for k, (it, r) in enumerate(zip(t.items, rows, strict=True)):
        shown = it.to_json(pool)
        got = (it.kind, it.purpose, shown["env_index"], shown["start_state"])
        want = (r["kind"], r["purpose"], int(r["env_index"]), json.loads(r["start_state"]))
        if got != want:
            raise ReplayMismatch(f"item {k}: the teacher rebuilt from the answers serves "
                                 f"{got[:3]}, but the export has {want[:3]}")
    return t


def responses_of(payloads: list[dict]) -> list[dict[str, Any]]:
    """Teacher responses from stored `item_done` payloads, in order."""
    return [{"actions": list(p["actions"])} if p.get("actions") is not None else {}
            for p in payloads]


class LiveTeaching:
    """Pools, games and (cached) teachers of one server or decision worker."""

    def __init__(self) -> None:
        self._pools: dict[tuple[str, str], LessonPool] = {}
        self._games: dict[tuple[str, str, int], dict] = {}
        self._teachers: OrderedDict[tuple, list[ClosedLoopTeacher]] = OrderedDict()
        self._locks: dict[tuple, threading.Lock] = {}
        self._lock = threading.Lock()
        self._pool_lock = threading.Lock()

    # -- derived data ----------------------------------------------------------------------
    def pool(self, study: dict, domain: str) -> LessonPool:
        key = (study["version"], domain)
        with self._pool_lock:
            if key not in self._pools:
                self._pools[key] = pool_from_cell(study["closed_loop"][domain])
            return self._pools[key]

    def warm(self, study: dict) -> None:
        """Build every closed-loop pool of a study now (at server start)."""
        for domain in study.get("closed_loop", {}):
            self.pool(study, domain)

    def game(self, study: dict, domain: str, demo: int) -> dict:
        """The playable table of a test started at pool demo `demo` (cached)."""
        key = (study["version"], domain, demo)
        g = self._games.get(key)
        if g is None:
            g = game_from_batch(self.pool(study, domain).ds, demo)
            with self._lock:
                if len(self._games) >= MAX_GAMES:
                    self._games.pop(next(iter(self._games)))
                self._games[key] = g
        return g

    # -- teachers --------------------------------------------------------------------------
    def session_lock(self, session_pk: int, domain: str) -> threading.Lock:
        with self._lock:
            return self._locks.setdefault((session_pk, domain), threading.Lock())

    def teacher(self, study: dict, session_pk: int, session_seed: int, domain: str,
                responses: list[dict], served: list[list] | None = None) -> ClosedLoopTeacher:
        """The teacher that has seen exactly `responses` (hold `session_lock` around its use).

        A cached teacher whose responses are a prefix of these is brought up to date; any
        other is ignored, and the session is replayed from the responses. With `served`
        (the stored items, ``[kind, demo]`` each), a teacher that would have served others
        raises `ReplayMismatch` and is not kept.
        """
        key = (session_pk, domain)
        with self._lock:
            cands = list(self._teachers.get(key, []))
        best = None
        for t in cands:
            n = len(t.responses)
            if n <= len(responses) and t.responses == responses[:n] and (
                    best is None or n > len(best.responses)):
                best = t
        pool = self.pool(study, domain)
        if best is None:
            best = ClosedLoopTeacher.replay(pool, responses,
                                            settings=settings_of(study["closed_loop"][domain]),
                                            seed=teacher_seed(session_seed, domain))
        else:
            for r in responses[len(best.responses):]:
                best.next()
                best.observe(r)
        if served is not None:
            check_served(best, served)
        self._remember(key, best)
        return best

    def _remember(self, key: tuple, t: ClosedLoopTeacher) -> None:
        with self._lock:
            kept = [x for x in self._teachers.pop(key, []) if x is not t][-1:]
            self._teachers[key] = [*kept, t]
            while len(self._teachers) > MAX_TEACHERS:
                old, _ = self._teachers.popitem(last=False)
                self._locks.pop(old, None)

    def decide(self, study: dict, session_pk: int, session_seed: int, domain: str,
               responses: list[dict],
               served: list[list] | None = None) -> tuple[Item | None, dict | None]:
        """The item after `responses` and the belief summary when it was chosen (both
        memoized on the teacher, so asking again costs nothing)."""
        with self.session_lock(session_pk, domain):
            t = self.teacher(study, session_pk, session_seed, domain, responses, served)
            item, summary = _decided(t)
            if item is not None and item.kind == "test":
                self.game(study, domain, item.demo)  # the page's table, built now
        return item, summary


def _decided(t: ClosedLoopTeacher) -> tuple[Item | None, dict | None]:
    """`t.next()` and its belief summary, memoized on the teacher."""
    memo = getattr(t, "_live_decided", None)
    if memo is not None and memo[0] == len(t.responses):
        return memo[1], memo[2]
    item = t.next()
    summary = None if item is None else item_summary(t, item)
    # kept on the teacher itself, so the memo goes wherever the teacher is cached
    t._live_decided = (len(t.responses), item, summary)  # type: ignore[attr-defined]
    return item, summary


def item_summary(t: ClosedLoopTeacher, item: Item) -> dict:
    """The belief summary stored with an item when it is chosen. Feedback is chosen before
    the failed answer's update (`ClosedLoopTeacher.as_chosen`), so its summary is the
    belief as the answer arrived, and the update runs in the decision made ahead, while the
    participant studies the feedback."""
    pool, belief = t.as_chosen
    return {"expected_area": float(belief.expected_area()),
            "predicted_optimal": item.predicted_optimal,
            "predicted_held_out": pool.held_out_mass(belief.particles, belief.weights),
            "progress": float(t.progress())}


def game_from_batch(ds: Any, demo: int) -> dict:  # noqa: ANN401 - a DemoSet
    """`games.build_game` for the start of pool demo `demo`, read from the domain's compiled
    transition arrays (the same table, about ten times faster): only the moves that end the
    game ask the instance for the terminal state they reach."""
    b = ds.batch
    e, start = int(ds.env[demo]), int(ds.start[demo])
    inst, states, sink = b.instances[e], b.states[e], b.sink
    ns, feat = b.next_state[e], b.features[e]
    index: dict[tuple, int] = {("r", start): 0}
    nodes: list[tuple] = [("r", start)]
    shown = [states[start]]
    nxt: list[list[int] | None] = []
    phi: list[list[list[float]] | None] = []
    i = 0
    while i < len(nodes):
        kind, s = nodes[i]
        i += 1
        if kind == "t":
            nxt.append(None)
            phi.append(None)
            continue
        row = []
        for a in range(b.A):
            j = int(ns[s, a])
            key: tuple = ("r", j)
            if j == sink:
                s2, _, _ = inst.step(states[s], a)
                key = ("t", s2)
            if key not in index:
                index[key] = len(nodes)
                nodes.append(key)
                shown.append(key[1] if key[0] == "t" else states[j])
            row.append(index[key])
        nxt.append(row)
        phi.append(feat[s].tolist())
    return {"actions": list(b.actions),
            "states": [to_jsonable(inst.state_to_json(x)) for x in shown],
            "next": nxt, "terminal": [k == "t" for k, _ in nodes], "phi": phi}


def path_states(game: dict, actions: list[str]) -> list[dict]:
    """The JSON states of a move list played in `game` from its start."""
    s, out = 0, [game["states"][0]]
    for a in actions:
        s = game["next"][s][game["actions"].index(a)]
        out.append(game["states"][s])
    return out
