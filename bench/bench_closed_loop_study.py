"""Load test of the live closed_loop condition: N concurrent participants at a person's
pace (one event every --pace seconds each), over loopback; by default half closed-loop and
half open-loop (`proposed`).

Starts `cfteach serve` (--servers of them, on one database) in subprocesses on 127.0.0.1
with a skateboard study (placeholder post-tests from `--preview`; the teacher with its
default 1,000 particles), runs every participant at once from consent to completion, each
waiting `--pace` s between its events (starts spread over the first interval), and times
every request. With several servers each request goes to the next server in turn (a proxy
without sticky sessions: the hardest case for consistency), or with --sticky each session
to one of them. Prints p50/p99 of the page
(GET /api/state), of every event (POST), and of the closed-loop decisions (from an
`item_done` POST until the page has the next item, through the "preparing" answers and
`GET /api/state?wait=` calls that wait for it), then checks in the database that every
acknowledged event was stored exactly once. `--attackers K` adds K closed-loop sessions that
send refused answers and page reads at their rate limits for the whole run; compare the
real participants' figures with and without them.

Every configuration at once (about 12 to 14 minutes on an idle 2-core machine; one table, the
load average recorded per row; see bench/closed_loop_suite.py):

    source scripts/postgres-for-tests
    .venv/bin/python bench/bench_closed_loop_study.py --suite --db "$CFTEACH_TEST_POSTGRES_URL"

One configuration:

    .venv/bin/python bench/bench_closed_loop_study.py                  # SQLite, 100 + 100
    .venv/bin/python bench/bench_closed_loop_study.py --attackers 2
    .venv/bin/python bench/bench_closed_loop_study.py --db "$CFTEACH_TEST_POSTGRES_URL"
    .venv/bin/python bench/bench_closed_loop_study.py --db "$CFTEACH_TEST_POSTGRES_URL" \
        --servers 2 --decision-workers 1
    .venv/bin/python bench/bench_closed_loop_study.py --refusal-cost 300
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import sys
import tempfile
import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import numpy as np

import study_db_check
from cfteach.study.bot import run_participant
from cfteach.study.build import init_study, preview_sources
from cfteach.study.db import drop_schema, make_engine
from cfteach.study.livesrv import serving_process

MAX_PARTICIPANTS = 400


class PacedClient:
    """httpx's get/post, one event per `pace` seconds, every request timed by kind."""

    def __init__(self, client: httpx.Client, pace: float, times: dict[str, list[float]],
                 lock: threading.Lock) -> None:
        self.client, self.pace, self.times, self.lock = client, pace, times, lock
        self.last = time.monotonic()
        self.deciding: float | None = None  # perf_counter() of the item_done being decided

    def _timed(self, kind: str, fn: Any, *a: Any, **k: Any) -> httpx.Response:  # noqa: ANN401
        """One request, timed; a transport error (reset, refused connection) is counted and
        the request sent once more, as the page does (an event keeps its id: never stored
        twice)."""
        t0 = time.perf_counter()
        try:
            r = fn(*a, **k)
        except httpx.TransportError as e:
            with self.lock:
                self.times.setdefault("transport_errors", []).append(0.0)
                self.times.setdefault("transport_error_kinds", []).append(repr(e)[:120])
            r = fn(*a, **k)
        dt = time.perf_counter() - t0
        with self.lock:
            self.times[kind].append(dt)
        return r

    def get(self, *a: Any, **k: Any) -> httpx.Response:  # noqa: ANN401
        kind = "wait" if k.get("params", {}).get("wait") else "page"
        r = self._timed(kind, self.client.get, *a, **k)
        self._decided(r)
        return r

    def _decided(self, r: httpx.Response) -> None:
        """Close the decision being timed once the page has its next item."""
        if self.deciding is None or r.status_code != 200:
            return
        body = r.json()
        if not body.get("state", body)["step"].get("preparing"):
            with self.lock:
                self.times["decision"].append(time.perf_counter() - self.deciding)
            self.deciding = None

    def post(self, url: str, *a: Any, json: dict | None = None, **k: Any) -> httpx.Response:  # noqa: ANN401
        if url != "/api/event":  # starting the session
            return self._timed("other", self.client.post, url, *a, json=json, **k)
        wait = self.pace - (time.monotonic() - self.last)
        if wait > 0:
            time.sleep(wait)
        self.last = time.monotonic()
        if json and json.get("type") == "item_done":
            self.deciding = time.perf_counter()
        r = self._timed("event", self.client.post, url, *a, json=json, **k)
        with self.lock:
            self.times.setdefault(f"type:{json['type']}", []).append(self.times["event"][-1])
        self._decided(r)
        return r


class RoundRobin:
    """httpx-like get/post sending each request to the next server in turn."""

    def __init__(self, clients: list[httpx.Client]) -> None:
        self.clients, self.n = clients, 0

    def _next(self) -> httpx.Client:
        self.n += 1
        return self.clients[self.n % len(self.clients)]

    def get(self, *a: Any, **k: Any) -> httpx.Response:  # noqa: ANN401
        return self._next().get(*a, **k)

    def post(self, *a: Any, **k: Any) -> httpx.Response:  # noqa: ANN401
        return self._next().post(*a, **k)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", "--participants", type=int, default=200)
    ap.add_argument("--pace", type=float, default=2.0, help="seconds between one "
                    "participant's events")
    ap.add_argument("--max-items", type=int, default=12, help="teacher's max_items")
    ap.add_argument("--teacher", default="", help="more teacher settings for the study file "
                    "as field=value,... (e.g. n_particles=250; default: the teacher's own)")
    ap.add_argument("--db", default=None, help="database URL (default: a fresh SQLite file)")
    ap.add_argument("--conditions", default="closed_loop,proposed",
                    help="study conditions (assignment balances over them)")
    ap.add_argument("--servers", type=int, default=1, help="`cfteach serve` processes on "
                    "the one database (SQLite or PostgreSQL)")
    ap.add_argument("--decision-workers", type=int, default=2, help="per server")
    ap.add_argument("--sticky", action="store_true", help="with --servers > 1, send each "
                    "participant's requests to one server (as a proxy routing by session "
                    "token does) instead of to the next server in turn")
    ap.add_argument("--attackers", type=int, default=0, help="closed-loop sessions sending "
                    "refused answers and page reads at their rate limits")
    ap.add_argument("--refusal-cost", type=int, default=0, metavar="N", help="instead: send "
                    "N refused closed-loop answers of each kind from one session and print "
                    "the server's CPU per refusal")
    ap.add_argument("--timeout", type=float, default=900.0, help="give up after (s)")
    ap.add_argument("--study", type=Path, default=None, help="a study folder made by an "
                    "earlier run (skateboard, the same --conditions and --max-items)")
    ap.add_argument("--json-out", type=Path, default=None, help="also write the figures here")
    ap.add_argument("--suite-teacher", default="n_particles=250", help="--suite: the "
                    "live-teacher row's settings (field=value,...)")
    ap.add_argument("--suite", action="store_true", help="run every configuration (SQLite, "
                    "PostgreSQL from --db, attackers, 1 and 2 servers) and print one table")
    args = ap.parse_args()
    if args.suite:
        from closed_loop_suite import run_suite

        return run_suite(args, Path(__file__))
    if not 1 <= args.participants <= MAX_PARTICIPANTS:
        ap.error(f"--participants must be 1..{MAX_PARTICIPANTS}")
    if args.pace < 0.2:
        ap.error("--pace must be at least 0.2 s")
    tmp = Path(tempfile.mkdtemp(prefix="cfteach-cl-load-"))
    study = args.study or make_study(tmp / "study", args)
    db = args.db or f"sqlite:///{tmp / 'load.db'}"
    if db.startswith("postgresql"):
        engine = make_engine(db)
        drop_schema(engine)
        engine.dispose()
    if args.refusal_cost:
        return _refusal_cost(study, db, args.refusal_cost)
    with contextlib.ExitStack() as stack:
        servers = [stack.enter_context(serving_process(
            study, "--db", db, "--sessions-per-minute", "0", "--researcher-token", "bench",
            "--decision-workers", str(args.decision_workers), timeout=600))
            for _ in range(args.servers)]
        bases = [b for b, _ in servers]
        pids = [p.pid for _, p in servers]
        cpu0, own0, load0 = _split_cpu(pids), _own_cpu(), os.getloadavg()[0]
        stop = threading.Event()
        attackers = _attackers(bases, args, stop)
        try:
            sent, times, wall = _run(bases, args)
        except Exception:
            for _, p in servers:
                if p.poll() is not None:  # a server died: say why
                    print(f"server {p.pid} exited with {p.returncode}: "
                          f"{p.stderr.read()[-3000:]}", file=sys.stderr)
            raise
        stop.set()
        for t in attackers:
            t.join(30)
        cpu1 = _split_cpu(pids)
        cpu = (cpu1[0] - cpu0[0], cpu1[1] - cpu0[1], _own_cpu() - own0)
    print(f"load average at start {load0:.1f}")
    return _report(db, sent, times, wall, cpu, args, load0)


def make_study(folder: Path, args: argparse.Namespace) -> Path:
    """The benchmark's skateboard study (placeholder post-tests, 10 ms demonstration steps)."""
    from cfteach.cli.simulate_cmd import _teacher_settings

    conds = [c.strip() for c in args.conditions.split(",") if c.strip()]
    extra = [x for x in args.teacher.split(",") if x.strip()]
    init_study(folder, preview_sources(["skateboard"]), demo_step_ms=10, conditions=conds,
               teacher={"max_items": args.max_items, **_teacher_settings(extra)})
    return folder


def _cpu(pid: int) -> float:
    """CPU seconds (user + system) a process has used so far (Linux /proc)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _split_cpu(pids: list[int]) -> tuple[float, float]:
    """CPU seconds of the server processes and of their children (the decision workers)."""
    own = kids_cpu = 0.0
    for pid in pids:
        kids = Path(f"/proc/{pid}/task/{pid}/children")
        children = kids.read_text().split() if kids.exists() else []
        own += _cpu(pid)
        kids_cpu += sum(_cpu(int(c)) for c in children)
    return own, kids_cpu


def _tree_cpu(pids: list[int]) -> float:
    """CPU seconds of the server processes and their children (the decision workers)."""
    return sum(_split_cpu(pids))


def _refusal_cost(study: Path, db: str, n: int) -> int:
    """Server CPU (server process and its decision workers) per refused request."""
    with serving_process(study, "--db", db, "--events-per-minute", "0",
                         "--states-per-minute", "0", "--decision-workers", "1",
                         timeout=600) as (base, proc), \
            httpx.Client(base_url=base, timeout=60) as c:
        for j in range(20):
            tok = c.post("/api/session", json={"prolific_pid": f"COST{j:02d}xx"}).json()["token"]
            run_participant(c, None, token=tok, stop_after=6)
            h = {"X-Session-Token": tok}
            st = c.get("/api/state", headers=h, params={"wait": 5}).json()
            if st["step"]["kind"] == "closed_loop":
                break
        step = st["step_index"]
        time.sleep(3)  # the decision after the first item, made ahead, is over
        kinds = {"wrong item (409 wrong_item)": ("item_done", {"item": 99}),
                 "unwatched demonstration (409 demos_unwatched)": ("item_done", {"item": 0}),
                 "actions on a demonstration (422 bad_payload)": (
                     "item_done", {"item": 0, "actions": ["up"] * 40}),
                 "wrong step, no closed-loop work (409 wrong_step)": ("continue", {})}
        print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        for label, (type_, payload) in kinds.items():
            cpu0 = _tree_cpu([proc.pid])
            for _ in range(n):
                r = c.post("/api/event", headers=h, json={
                    "event_id": uuid.uuid4().hex, "type": type_, "payload": payload,
                    "step_index": step + (5 if type_ == "continue" else 0)})
                assert r.status_code in (409, 422), r.text
            cpu = (_tree_cpu([proc.pid]) - cpu0) / n * 1000
            print(f"{label}: server CPU {cpu:.2f} ms per refusal (n={n})")
    return 0


def _attackers(bases: list[str], args: argparse.Namespace,
               stop: threading.Event) -> list[threading.Thread]:
    """Closed-loop sessions that, for the whole run, send `item_done` answers the server
    refuses (a wrong item: validated, never decided) at the event limit (600 per minute
    weighted, an answer weighing 4) and page reads at the page-read limit (120 per minute)."""
    threads = []
    for k in range(args.attackers):
        def attack(k: int = k) -> None:
            with httpx.Client(base_url=bases[0], timeout=60) as c:
                tok, step = None, None
                for j in range(20):  # until assignment gives a closed-loop session
                    r = c.post("/api/session", json={"prolific_pid": f"ATTACK{k:02d}{j:02d}x"})
                    tok = r.json()["token"]
                    run_participant(c, None, token=tok, stop_after=6)
                    st = c.get("/api/state", headers={"X-Session-Token": tok}).json()
                    if st["step"]["kind"] == "closed_loop":
                        step = st["step_index"]
                        break
                if step is None:
                    return
                h = {"X-Session-Token": tok}
                period, nxt = 60 / (600 / 4 + 120), time.monotonic()
                n = 0
                while not stop.is_set():
                    n += 1
                    if n % 270 < 150:
                        c.post("/api/event", headers=h, json={
                            "event_id": uuid.uuid4().hex, "step_index": step,
                            "type": "item_done", "payload": {"item": 999}})
                    else:
                        c.get("/api/state", headers=h)
                    nxt += period
                    time.sleep(max(0.0, nxt - time.monotonic()))
        t = threading.Thread(target=attack, daemon=True)
        t.start()
        threads.append(t)
    return threads


def _own_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _run(bases: list[str], args: argparse.Namespace) -> tuple[dict[str, int], dict, float]:
    times: dict[str, list[float]] = {"page": [], "event": [], "decision": [], "other": [],
                                     "wait": []}
    lock = threading.Lock()
    deadline = time.monotonic() + args.timeout
    rng = random.Random(0)
    offsets = [rng.uniform(0, args.pace) for _ in range(args.participants)]

    # Every participant's clients are made before the clock starts: making one costs the
    # load generator ~15 ms of CPU (httpx builds a TLS context even for http://), and 200
    # made in the first 2 s, in this one process, delayed the generator's own requests by
    # seconds (the server timed those requests at p99 0.3 s, the generator at 1.6 s).
    # Idle connections are closed by us (2 s) before the server's keep-alive timeout.
    limits = httpx.Limits(max_connections=2, keepalive_expiry=2.0)
    clients = [[httpx.Client(base_url=b, timeout=60, limits=limits) for b in bases]
               for _ in range(args.participants)]

    def one(i: int) -> tuple[str, int]:
        time.sleep(offsets[i])
        cs = clients[i]
        # --sticky: each session on one server (a proxy hashing the session token)
        c = cs[0] if len(cs) == 1 else cs[i % len(cs)] if args.sticky else RoundRobin(cs)
        paced = PacedClient(c, args.pace, times, lock)
        out = run_participant(paced, {"prolific_pid": f"CLLOAD{i:06d}", "study_id": "B",
                                      "session_id": f"S{i}"})
        if time.monotonic() > deadline:
            raise TimeoutError("load test time limit reached")
        if out["state"]["step"]["kind"] != "complete":
            raise RuntimeError(f"participant {i} ended on {out['state']['step']['kind']}")
        return out["state"]["participant_id"], out["events"]

    try:
        t0 = time.perf_counter()
        with ThreadPoolExecutor(args.participants) as pool:
            sent = dict(pool.map(one, range(args.participants)))
        return sent, times, time.perf_counter() - t0
    finally:
        for cs in clients:
            for c in cs:
                c.close()


def _pct(xs: list[float]) -> str:
    if not xs:
        return "none"
    a = np.asarray(xs) * 1000
    return (f"p50 {np.percentile(a, 50):.0f} ms, p99 {np.percentile(a, 99):.0f} ms, "
            f"max {a.max():.0f} ms (n={len(a)})")


def _p99(xs: list[float]) -> float | None:
    return float(np.percentile(np.asarray(xs) * 1000, 99)) if xs else None


def _report(db: str, sent: dict[str, int], times: dict, wall: float,
            cpu: tuple[float, float], args: argparse.Namespace, load0: float) -> int:
    held = study_db_check.stored(db, skip_pid_prefix="ATTACK")
    stored, done = held.events, len(held.completed)
    lost, dup = held.lost(sent), held.duplicated(sent)
    kind = db.split(":")[0].split("+")[0]
    events = sum(sent.values())
    load1 = os.getloadavg()[0]
    print(f"database: {kind}; {args.servers} server process(es) x {args.decision_workers} "
          f"decision worker(s); teacher {args.teacher or 'default'}; participants: "
          f"{args.participants} at once ({args.conditions}),"
          f" one event per {args.pace:g} s each; attackers {args.attackers}; wall time "
          f"{wall:.0f} s; {events} events acknowledged ({events / wall:.0f}/s)")
    requests = sum(len(times[k]) for k in ("page", "event", "wait", "other"))
    conds = [c.strip() for c in args.conditions.split(",") if c.strip()]
    closed = args.participants // len(conds) if "closed_loop" in conds else 0
    decisions = len(times["decision"]) + closed  # + each session's first item
    server = cpu[0] + cpu[1]
    print(f"CPU: server {server:.0f} s ({server / wall:.2f} cores: web server "
          f"{cpu[0] / wall:.2f}, decision workers {cpu[1] / wall:.2f}), simulated participants"
          f" {cpu[2]:.0f} s ({cpu[2] / wall:.2f} cores); load average {load0:.1f} at start, "
          f"{load1:.1f} at end on {os.cpu_count()} cores")
    print(f"CPU per request (web server): {1000 * cpu[0] / max(1, requests):.1f} ms over "
          f"{requests} requests; per decision (workers): "
          f"{1000 * cpu[1] / max(1, decisions):.0f} ms over about {decisions}; "
          f"decisions {decisions / wall:.1f}/s")
    print(f"page (GET /api/state):       {_pct(times['page'])}")
    print(f"every event (POST):          {_pct(times['event'])}")
    print(f"decisions (item_done -> next item shown): {_pct(times['decision'])}")
    print(f"waits for a prepared item (GET ?wait=): {_pct(times['wait'])}")
    slow = sorted(((k[5:], np.percentile(v, 99) * 1000) for k, v in times.items()
                   if k.startswith("type:")), key=lambda x: -x[1])
    print("p99 by event type: " + ", ".join(f"{k} {ms:.0f} ms" for k, ms in slow))
    resets = times.get("transport_error_kinds", [])
    if resets:
        print(f"transport errors (each retried once): {len(resets)}, e.g. {resets[0]}")
    print(f"stored: {sum(stored.values())} events for {len(stored)} sessions; completed "
          f"{done}/{args.participants}; sessions with seq gaps {held.seq_gaps}; with item "
          f"gaps or repeats {held.item_gaps}")
    ok = (not lost and not dup and done == args.participants and held.seq_gaps == 0
          and held.item_gaps == 0)
    print("no event lost or duplicated" if ok else f"MISMATCH: lost {lost}, duplicated {dup}")
    if args.json_out:
        args.json_out.write_text(json.dumps({
            "db": kind, "servers": args.servers, "workers": args.decision_workers,
            "participants": args.participants, "pace": args.pace,
            "attackers": args.attackers, "teacher": args.teacher,
            "wall_s": wall, "events": events,
            "load_start": load0, "load_end": load1, "server_cores": server / wall,
            "web_cores": cpu[0] / wall, "worker_cores": cpu[1] / wall,
            "client_cores": cpu[2] / wall,
            "p99_ms": {k: _p99(times[k]) for k in ("decision", "event", "page")},
            "transport_errors": len(resets), "lost": lost, "duplicated": dup,
            "completed": done, "ok": ok}))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
