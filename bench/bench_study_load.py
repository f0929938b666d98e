"""Load test of the study server: N simulated participants, C at a time, over loopback.

Starts `cfteach serve` in a subprocess on 127.0.0.1 (a toy study, or --study DIR), runs
each participant through the whole study with the HTTP API (consent to completion: ~50
events each), then checks in the database that every acknowledged event was stored exactly
once and every participant completed. Prints participants/s and events/s.

    .venv/bin/python bench/bench_study_load.py                       # SQLite
    .venv/bin/python bench/bench_study_load.py --db "$CFTEACH_TEST_POSTGRES_URL"
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
from sqlalchemy import func, select
from tqdm import tqdm

from cfteach.study.bot import run_participant
from cfteach.study.build import init_study, toy_sources
from cfteach.study.db import drop_schema, make_engine
from cfteach.study.livesrv import free_port
from cfteach.study.models import Event, Session, TestResponse

MAX_PARTICIPANTS = 2000
MAX_CONCURRENCY = 64


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", "--participants", type=int, default=60)
    ap.add_argument("-c", "--concurrency", type=int, default=8)
    ap.add_argument("--db", default=None, help="database URL (default: a fresh SQLite file)")
    ap.add_argument("--study", type=Path, default=None, help="study folder (default: toy)")
    ap.add_argument("--timeout", type=float, default=600.0, help="give up after (s)")
    args = ap.parse_args()
    if not 1 <= args.participants <= MAX_PARTICIPANTS:
        ap.error(f"--participants must be 1..{MAX_PARTICIPANTS}")
    if not 1 <= args.concurrency <= MAX_CONCURRENCY:
        ap.error(f"--concurrency must be 1..{MAX_CONCURRENCY}")
    tmp = Path(tempfile.mkdtemp(prefix="cfteach-load-"))
    study = args.study
    if study is None:
        study = tmp / "study"
        # 10 ms per demonstration step: bots wait out each replay (the server times it).
        init_study(study, toy_sources(), demo_step_ms=10)
    db = args.db or f"sqlite:///{tmp / 'load.db'}"
    if db.startswith("postgresql"):
        engine = make_engine(db)
        drop_schema(engine)  # a clean schema for a clean count
        engine.dispose()
    port = free_port()
    env = {**os.environ, "CFTEACH_LOG": "warning"}
    server = subprocess.Popen(
        [sys.executable, "-c", "from cfteach.cli import main; main()", "serve",
         "--study", str(study), "--db", db, "--host", "127.0.0.1", "--port", str(port),
         "--researcher-token", "bench", "--sessions-per-minute", "0"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    base = f"http://127.0.0.1:{port}"
    try:
        _wait(base, server)
        sent = _run(base, args)
        return _verify(db, sent, args)
    finally:
        server.terminate()
        server.wait(timeout=20)


def _wait(base: str, server: subprocess.Popen) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise SystemExit(f"server exited: {server.stderr.read().decode()[-2000:]}")
        try:
            if httpx.get(base + "/", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            time.sleep(0.2)
    raise SystemExit("server did not start within 60 s")


def _run(base: str, args: argparse.Namespace) -> dict[str, int]:
    deadline = time.monotonic() + args.timeout
    sent: dict[str, int] = {}

    def one(i: int) -> tuple[str, int]:
        if time.monotonic() > deadline:
            raise TimeoutError("load test time limit reached")
        with httpx.Client(base_url=base, timeout=60) as client:
            out = run_participant(client, {"prolific_pid": f"LOAD{i:06d}", "study_id": "B"})
        if out["state"]["step"]["kind"] != "complete":
            raise RuntimeError(f"participant {i} ended on {out['state']['step']['kind']}")
        return out["state"]["participant_id"], out["events"]

    t0 = time.perf_counter()
    with ThreadPoolExecutor(args.concurrency) as pool, tqdm(
            total=args.participants, unit="participant", file=sys.stderr,
            disable=not sys.stderr.isatty()) as bar:
        for pid, n in pool.map(one, range(args.participants)):
            sent[pid] = n
            bar.update()
    dt = time.perf_counter() - t0
    events = sum(sent.values())
    kind = args.db.split(":")[0] if args.db else "sqlite"
    print(f"database: {kind}; participants: {args.participants}; concurrency: "
          f"{args.concurrency}; wall time: {dt:.1f} s")
    print(f"throughput: {args.participants / dt:.2f} participants/s, {events / dt:.0f} "
          f"events/s ({events} events acknowledged)")
    return sent


def _verify(db: str, sent: dict[str, int], args: argparse.Namespace) -> int:
    engine = make_engine(db)
    with engine.connect() as conn:
        stored = dict(conn.execute(select(Session.participant_id, func.count(Event.id))
                                   .join(Event, Event.session_pk == Session.id)
                                   .group_by(Session.participant_id)).all())
        done = conn.scalar(select(func.count()).select_from(Session)
                           .where(Session.status == "completed"))
        tests = conn.scalar(select(func.count()).select_from(TestResponse))
        gaps = conn.scalar(select(func.count()).select_from(
            select(Event.session_pk).group_by(Event.session_pk)
            .having(func.max(Event.seq) != func.count()).subquery()))
    engine.dispose()
    lost = {p: n - stored.get(p, 0) for p, n in sent.items() if stored.get(p, 0) != n}
    print(f"stored: {sum(stored.values())} events for {len(stored)} sessions; completed "
          f"{done}/{args.participants}; test responses {tests}; sessions with seq gaps {gaps}")
    ok = not lost and done == args.participants and gaps == 0
    print("no event lost or duplicated" if ok else f"MISMATCH: {lost}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
