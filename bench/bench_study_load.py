"""Load test of the study server: N participants at once, each at a person's pace, with Locust.

Starts `cfteach serve` in a subprocess on 127.0.0.1 (a toy study, or --study DIR), then
Locust runs N simulated participants at the same time for --duration seconds. Each one walks
the study through the HTTP API (consent to completion, about 50 events, the same bot the
tests use) with a think time before every event: one event per --pace seconds on average.
A participant who finishes is replaced by a new one, so N stay active until the end.

It reports the latency of every request (p50/p99/max, exact, from Locust's request events),
failed requests, and then checks in the database that every event a participant got 200 for
is stored exactly once, without sequence gaps, and that every finished participant is
`completed` there.

    .venv/bin/python bench/bench_study_load.py -n 200 --duration 180            # SQLite
    .venv/bin/python bench/bench_study_load.py -n 200 --db "$CFTEACH_TEST_POSTGRES_URL"
"""

from __future__ import annotations

import study_load_users as users  # first: Locust patches the standard library for gevent

# isort: split
import argparse
import inspect
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import gevent
import httpx
import numpy as np
from locust.env import Environment

import study_db_check
from cfteach.cli.study_cmd import serve
from cfteach.study.build import init_study, toy_sources
from cfteach.study.db import drop_schema, make_engine
from cfteach.study.livesrv import free_port

MAX_PARTICIPANTS = 1000
MAX_DURATION = 3600.0
GRACE = 90.0  # seconds the last requests get to finish after the deadline


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", "--participants", type=int, default=200,
                    help=f"participants active at once (1..{MAX_PARTICIPANTS})")
    ap.add_argument("--duration", type=float, default=180.0,
                    help="seconds of load; no event is sent after that")
    ap.add_argument("--pace", type=float, default=2.0,
                    help="mean seconds between two events of one participant (think time)")
    ap.add_argument("--arrivals", type=float, default=10.0,
                    help="new participants per second while the N first ones arrive")
    ap.add_argument("--db", default=None, help="database URL (default: a fresh SQLite file)")
    ap.add_argument("--study", type=Path, default=None, help="study folder (default: toy)")
    ap.add_argument("--demo-step-ms", type=int, default=10,
                    help="replay speed of demonstrations (the server refuses 'watched' "
                         "claims made faster than a replay lasts)")
    args = ap.parse_args()
    if not 1 <= args.participants <= MAX_PARTICIPANTS:
        ap.error(f"--participants must be 1..{MAX_PARTICIPANTS}")
    if not 1 <= args.duration <= MAX_DURATION:
        ap.error(f"--duration must be 1..{MAX_DURATION:.0f} seconds")
    if not 0 < args.pace <= 60:
        ap.error("--pace must be in (0, 60] seconds")
    if not 0 < args.arrivals <= 1000:
        ap.error("--arrivals must be in (0, 1000] per second")
    tmp = Path(tempfile.mkdtemp(prefix="cfteach-load-"))
    study = args.study
    if study is None:
        study = tmp / "study"
        # Fast replays: bots wait out each one (the server times it).
        init_study(study, toy_sources(), demo_step_ms=args.demo_step_ms)
    db = args.db or f"sqlite:///{tmp / 'load.db'}"
    if db.startswith("postgresql"):
        engine = make_engine(db)
        drop_schema(engine)  # a clean schema for a clean count
        engine.dispose()
    port = free_port()
    log = open(tmp / "server.log", "wb")  # noqa: SIM115  (a file, not a pipe: never fills up)
    server = subprocess.Popen(_serve_command(study, db, port, args.demo_step_ms),
                              env={**os.environ, "CFTEACH_LOG": "warning"},
                              stdout=subprocess.DEVNULL, stderr=log)
    base = f"http://127.0.0.1:{port}"
    try:
        _wait(base, server, tmp / "server.log")
        cpu0, load0, mine0 = _cpu_seconds(server.pid), os.getloadavg(), time.process_time()
        latencies, wall, loads = _run(base, args)
        cpu = (_cpu_seconds(server.pid) - cpu0, time.process_time() - mine0)
        load = (load0[0], float(np.mean(loads)), max(loads))
    finally:
        server.terminate()
        server.wait(timeout=30)
        log.close()
    check = _verify(db, users.Plan.tally)
    _report(args, db, latencies, wall, cpu, load, check)
    ok = not users.Plan.tally.failures and not check["problems"]
    return 0 if ok else 1


def _serve_command(study: Path, db: str, port: int, demo_step_ms: int) -> list[str]:
    cmd = [sys.executable, "-c", "from cfteach.cli import main; main()", "serve",
           "--study", str(study), "--db", db, "--host", "127.0.0.1", "--port", str(port),
           "--researcher-token", "bench", "--sessions-per-minute", "0"]
    # Servers that time demonstration replays on their own clock take the replay speed;
    # older ones read it from the study folder only (the toy study is built with it).
    if "demo_step_ms" in inspect.signature(serve).parameters:
        cmd += ["--demo-step-ms", str(demo_step_ms)]
    return cmd


def _wait(base: str, server: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise SystemExit(f"server exited: {log.read_text()[-2000:]}")
        try:
            if httpx.get(base + "/", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            time.sleep(0.2)
    raise SystemExit("server did not start within 60 s")


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (Linux /proc), to tell server cost from client's."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _run(base: str, args: argparse.Namespace) -> tuple[dict[str, list[float]], float,
                                                      list[float]]:
    """Run the participants until the deadline; returns latencies (ms) by request name, the
    wall time and the machine's 1-minute load average sampled along the way."""
    latencies: dict[str, list[float]] = defaultdict(list)

    def on_request(name: str, response_time: float, **_kw: Any) -> None:
        latencies[name].append(response_time)

    users.Plan.pace = args.pace
    users.Plan.tally = users.Tally()
    env = Environment(user_classes=[users.Participant], host=base)
    env.events.request.add_listener(on_request)
    runner = env.create_local_runner()
    t0 = time.monotonic()
    users.Plan.deadline = t0 + args.duration
    runner.start(args.participants, spawn_rate=args.arrivals)
    runner.spawning_greenlet.join()  # all participants have arrived
    # Participants stop by themselves at the deadline, between two requests.
    loads = [os.getloadavg()[0]]
    while runner.user_count and time.monotonic() < users.Plan.deadline + GRACE:
        gevent.sleep(0.5)
        if time.monotonic() < users.Plan.deadline:
            loads.append(os.getloadavg()[0])
    wall = time.monotonic() - t0
    runner.quit()  # kills only what is still waiting for an answer after the grace time
    return latencies, wall, loads


def _verify(db: str, tally: users.Tally) -> dict[str, Any]:
    """Compare what participants were told with what the database holds."""
    held = study_db_check.stored(db)
    stored, completed, gaps = held.events, held.completed, held.seq_gaps
    lost = held.lost(tally.acked)
    # Stored but never acknowledged: allowed only for events still without an answer.
    duplicated = held.duplicated(tally.acked, tally.in_flight)
    problems = []
    if lost:
        problems.append(f"{lost} acknowledged events missing from the database")
    if duplicated:
        problems.append(f"{duplicated} events stored more than acknowledged")
    if gaps:
        problems.append(f"{gaps} sessions with gaps in their event sequence")
    if set(stored) != set(tally.acked):
        problems.append(f"{len(stored)} sessions stored, {len(tally.acked)} started")
    if not set(tally.completed) <= completed:
        problems.append(f"{len(set(tally.completed) - completed)} finished participants "
                        "not marked completed")
    return {"stored": sum(stored.values()), "lost": lost, "duplicated": duplicated,
            "gaps": gaps, "completed": len(completed), "problems": problems}


def _report(args: argparse.Namespace, db: str, latencies: dict[str, list[float]],
            wall: float, cpu: tuple[float, float], load: tuple,
            check: dict[str, Any]) -> None:
    tally = users.Plan.tally
    kind = db.split(":")[0].split("+")[0]
    every = np.concatenate([np.asarray(v) for v in latencies.values()] or [[np.nan]])
    events = sum(tally.acked.values())
    print(f"{kind}: {args.participants} participants at once, one event per {args.pace:g} s "
          f"each, {wall:.0f} s ({args.duration:g} s of load)")
    print(f"  participants started {tally.started}, finished {len(tally.completed)}; "
          f"requests {every.size} ({every.size / wall:.0f}/s), events acknowledged "
          f"{events} ({events / wall:.0f}/s)")
    for name in sorted(latencies):
        ms = np.asarray(latencies[name])
        print(f"  {name:<18} n={ms.size:<6} p50 {np.percentile(ms, 50):6.1f} ms  "
              f"p99 {np.percentile(ms, 99):6.1f} ms  max {ms.max():7.1f} ms")
    print(f"  CPU: server {cpu[0]:.0f} s ({100 * cpu[0] / wall:.0f}% of one core), these "
          f"participants {cpu[1]:.0f} s ({100 * cpu[1] / wall:.0f}%); load average "
          f"(1 min) {load[0]:.1f} at start, {load[1]:.1f} mean and {load[2]:.1f} max during "
          f"the run ({os.cpu_count()} cores)")
    print(f"  database: {check['stored']} events stored, {check['completed']} sessions "
          f"completed; lost {check['lost']}, duplicated {check['duplicated']}, sessions "
          f"with seq gaps {check['gaps']}")
    for f in tally.failures[:10]:
        print(f"  FAILED {f}")
    for p in check["problems"]:
        print(f"  MISMATCH {p}")
    print("\n| database | participants | events | p50 ms | p99 ms | max ms | errors | lost |")
    print("|---|---|---|---|---|---|---|---|")
    print(f"| {kind} | {args.participants} | {events} | {np.percentile(every, 50):.0f} | "
          f"{np.percentile(every, 99):.0f} | {every.max():.0f} | {len(tally.failures)} | "
          f"{check['lost']} |")


if __name__ == "__main__":
    raise SystemExit(main())
