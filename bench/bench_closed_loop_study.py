"""Load test of the live closed_loop condition: N concurrent closed-loop participants at a
person's pace (one event every --pace seconds each), over loopback.

Starts `cfteach serve` in a subprocess on 127.0.0.1 with a closed-loop-only skateboard
study (placeholder post-tests from `--preview`; the teacher with its default 1,000
particles), runs every participant at once from consent to completion, each waiting
`--pace` s between its events (starts spread over the first interval), and times every
request. Prints p50/p99 of the page (GET /api/state), of every event, and of the closed-loop
decisions (the `item_done` answers, whose response carries the next item), then checks in
the database that every acknowledged event was stored exactly once.

    .venv/bin/python bench/bench_closed_loop_study.py                  # SQLite, 100 x 2 s
    .venv/bin/python bench/bench_closed_loop_study.py --db "$CFTEACH_TEST_POSTGRES_URL"
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from sqlalchemy import func, select

from cfteach.study.bot import run_participant
from cfteach.study.build import init_study, preview_sources
from cfteach.study.db import drop_schema, make_engine
from cfteach.study.livesrv import serving_process
from cfteach.study.models import ClosedLoopItem, Event, Session

MAX_PARTICIPANTS = 200


class PacedClient:
    """httpx's get/post, one event per `pace` seconds, every request timed by kind."""

    def __init__(self, client: httpx.Client, pace: float, times: dict[str, list[float]],
                 lock: threading.Lock) -> None:
        self.client, self.pace, self.times, self.lock = client, pace, times, lock
        self.last = time.monotonic()

    def _timed(self, kind: str, fn: Any, *a: Any, **k: Any) -> httpx.Response:  # noqa: ANN401
        t0 = time.perf_counter()
        r = fn(*a, **k)
        dt = time.perf_counter() - t0
        with self.lock:
            self.times[kind].append(dt)
        return r

    def get(self, *a: Any, **k: Any) -> httpx.Response:  # noqa: ANN401
        return self._timed("page", self.client.get, *a, **k)

    def post(self, url: str, *a: Any, json: dict | None = None, **k: Any) -> httpx.Response:  # noqa: ANN401
        if url != "/api/event":  # starting the session
            return self._timed("other", self.client.post, url, *a, json=json, **k)
        wait = self.pace - (time.monotonic() - self.last)
        if wait > 0:
            time.sleep(wait)
        self.last = time.monotonic()
        kind = "decision" if json and json.get("type") == "item_done" else "event"
        r = self._timed(kind, self.client.post, url, *a, json=json, **k)
        with self.lock:
            dt = self.times[kind][-1]
            if kind == "decision":
                self.times["event"].append(dt)
            self.times.setdefault(f"type:{json['type']}", []).append(dt)
        return r


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", "--participants", type=int, default=100)
    ap.add_argument("--pace", type=float, default=2.0, help="seconds between one "
                    "participant's events")
    ap.add_argument("--max-items", type=int, default=12, help="teacher's max_items")
    ap.add_argument("--db", default=None, help="database URL (default: a fresh SQLite file)")
    ap.add_argument("--open-loop", action="store_true", help="the same run with the "
                    "'proposed' condition instead (a baseline for the machine's own load)")
    ap.add_argument("--timeout", type=float, default=900.0, help="give up after (s)")
    args = ap.parse_args()
    if not 1 <= args.participants <= MAX_PARTICIPANTS:
        ap.error(f"--participants must be 1..{MAX_PARTICIPANTS}")
    if args.pace < 0.2:
        ap.error("--pace must be at least 0.2 s")
    tmp = Path(tempfile.mkdtemp(prefix="cfteach-cl-load-"))
    study = tmp / "study"
    init_study(study, preview_sources(["skateboard"]), demo_step_ms=10,
               conditions=["proposed" if args.open_loop else "closed_loop"],
               teacher={"max_items": args.max_items})
    db = args.db or f"sqlite:///{tmp / 'load.db'}"
    if db.startswith("postgresql"):
        engine = make_engine(db)
        drop_schema(engine)
        engine.dispose()
    with serving_process(study, "--db", db, "--sessions-per-minute", "0",
                         "--researcher-token", "bench") as (base, proc):
        cpu0, own0 = _cpu(proc.pid), _own_cpu()
        sent, times, wall = _run(base, args)
        cpu = (_cpu(proc.pid) - cpu0, _own_cpu() - own0)
    return _report(db, sent, times, wall, cpu, args)


def _cpu(pid: int) -> float:
    """CPU seconds (user + system) a process has used so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _own_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _run(base: str, args: argparse.Namespace) -> tuple[dict[str, int], dict, float]:
    times: dict[str, list[float]] = {"page": [], "event": [], "decision": [], "other": []}
    lock = threading.Lock()
    deadline = time.monotonic() + args.timeout
    rng = random.Random(0)
    offsets = [rng.uniform(0, args.pace) for _ in range(args.participants)]

    def one(i: int) -> tuple[str, int]:
        time.sleep(offsets[i])
        limits = httpx.Limits(max_connections=2)
        with httpx.Client(base_url=base, timeout=60, limits=limits) as c:
            paced = PacedClient(c, args.pace, times, lock)
            out = run_participant(paced, {"prolific_pid": f"CLLOAD{i:06d}", "study_id": "B",
                                          "session_id": f"S{i}"})
        if time.monotonic() > deadline:
            raise TimeoutError("load test time limit reached")
        if out["state"]["step"]["kind"] != "complete":
            raise RuntimeError(f"participant {i} ended on {out['state']['step']['kind']}")
        return out["state"]["participant_id"], out["events"]

    t0 = time.perf_counter()
    with ThreadPoolExecutor(args.participants) as pool:
        sent = dict(pool.map(one, range(args.participants)))
    return sent, times, time.perf_counter() - t0


def _pct(xs: list[float]) -> str:
    if not xs:
        return "none"
    a = np.asarray(xs) * 1000
    return (f"p50 {np.percentile(a, 50):.0f} ms, p99 {np.percentile(a, 99):.0f} ms, "
            f"max {a.max():.0f} ms (n={len(a)})")


def _report(db: str, sent: dict[str, int], times: dict, wall: float,
            cpu: tuple[float, float], args: argparse.Namespace) -> int:
    engine = make_engine(db)
    with engine.connect() as conn:
        stored = dict(conn.execute(select(Session.participant_id, func.count(Event.id))
                                   .join(Event, Event.session_pk == Session.id)
                                   .group_by(Session.participant_id)).all())
        done = conn.scalar(select(func.count()).select_from(Session)
                           .where(Session.status == "completed"))
        items = conn.scalar(select(func.count()).select_from(ClosedLoopItem))
        gaps = conn.scalar(select(func.count()).select_from(
            select(Event.session_pk).group_by(Event.session_pk)
            .having(func.max(Event.seq) != func.count()).subquery()))
    engine.dispose()
    kind = db.split(":")[0].split("+")[0]
    events = sum(sent.values())
    who = "open-loop (proposed)" if args.open_loop else "closed-loop"
    print(f"database: {kind}; {who} participants: {args.participants} at once, one "
          f"event per {args.pace:g} s each; wall time {wall:.0f} s; {events} events "
          f"acknowledged ({events / wall:.0f}/s); {items} closed-loop items")
    print(f"CPU: server {cpu[0]:.0f} s ({cpu[0] / wall:.2f} cores), simulated participants "
          f"{cpu[1]:.0f} s ({cpu[1] / wall:.2f} cores); load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"page (GET /api/state):       {_pct(times['page'])}")
    print(f"every event (POST):          {_pct(times['event'])}")
    print(f"decisions (item_done POST):  {_pct(times['decision'])}")
    slow = sorted(((k[5:], np.percentile(v, 99) * 1000) for k, v in times.items()
                   if k.startswith("type:")), key=lambda x: -x[1])
    print("p99 by event type: " + ", ".join(f"{k} {ms:.0f} ms" for k, ms in slow))
    lost = {p: n - stored.get(p, 0) for p, n in sent.items() if stored.get(p, 0) != n}
    print(f"stored: {sum(stored.values())} events for {len(stored)} sessions; completed "
          f"{done}/{args.participants}; sessions with seq gaps {gaps}")
    ok = not lost and done == args.participants and gaps == 0
    print("no event lost or duplicated" if ok else f"MISMATCH: {lost}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
