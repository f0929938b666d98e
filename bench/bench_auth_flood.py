"""A real participant's request latency while another client floods the server with bad
session tokens.

Starts `cfteach serve` on 127.0.0.1 with `--forwarded-allow-ips 127.0.0.1`, so the two
clients can play two addresses (X-Forwarded-For 10.0.0.1 and 10.0.0.66). One simulated
participant walks the toy study alone, then again while `--flooders` threads send
GET /api/state with random well-formed (unknown) tokens as fast as they can. Prints the
participant's median and 90th-percentile request latency in both runs and the flood's
status codes (the flooder's address should be refused with 429 after
`--auth-failures-per-minute` failures, before any token lookup).

    .venv/bin/python bench/bench_auth_flood.py --flooders 4
"""

from __future__ import annotations

import argparse
import secrets
import statistics
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import httpx

from cfteach.study.bot import run_participant
from cfteach.study.build import init_study, toy_sources
from cfteach.study.livesrv import serving_process

MAX_FLOODERS = 16
MAX_SECONDS = 120


class Timed:
    """An httpx client that remembers how long each request took (ms)."""

    def __init__(self, client: httpx.Client) -> None:
        self.client, self.ms = client, []

    def _timed(self, method: str, *args, **kw):  # noqa: ANN002, ANN003, ANN202
        t0 = time.perf_counter()
        r = getattr(self.client, method)(*args, **kw)
        self.ms.append((time.perf_counter() - t0) * 1000)
        return r

    def get(self, *args, **kw):  # noqa: ANN002, ANN003, ANN201
        return self._timed("get", *args, **kw)

    def post(self, *args, **kw):  # noqa: ANN002, ANN003, ANN201
        return self._timed("post", *args, **kw)


def participant(base: str, pid: str) -> list[float]:
    with httpx.Client(base_url=base, timeout=60,
                      headers={"X-Forwarded-For": "10.0.0.1"}) as c:
        timed = Timed(c)
        out = run_participant(timed, {"prolific_pid": pid, "study_id": "B",
                                      "session_id": pid})
        if out["state"]["step"]["kind"] != "complete":
            raise RuntimeError("the participant did not finish")
        return timed.ms


def flood(base: str, stop: threading.Event, codes: Counter, deadline: float) -> None:
    with httpx.Client(base_url=base, timeout=10,
                      headers={"X-Forwarded-For": "10.0.0.66"}) as c:
        while not stop.is_set() and time.monotonic() < deadline:
            r = c.get("/api/state", headers={"X-Session-Token": secrets.token_urlsafe(32)})
            codes[r.status_code] += 1


def _summary(ms: list[float]) -> str:
    q = statistics.quantiles(ms, n=10)
    return f"median {statistics.median(ms):.1f} ms, p90 {q[-1]:.1f} ms over {len(ms)} requests"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flooders", type=int, default=4, help=f"threads (1..{MAX_FLOODERS})")
    ap.add_argument("--serve-args", default="", help="extra `cfteach serve` options")
    args = ap.parse_args()
    if not 1 <= args.flooders <= MAX_FLOODERS:
        ap.error(f"--flooders must be 1..{MAX_FLOODERS}")
    tmp = Path(tempfile.mkdtemp(prefix="cfteach-flood-"))
    init_study(tmp / "study", toy_sources())
    with serving_process(tmp / "study", "--db", f"sqlite:///{tmp / 'f.db'}",
                         "--forwarded-allow-ips", "127.0.0.1", "--sessions-per-minute", "0",
                         *args.serve_args.split()) as (base, _proc):
        print(f"alone: {_summary(participant(base, 'ALONE01'))}")
        stop, codes = threading.Event(), Counter()
        deadline = time.monotonic() + MAX_SECONDS
        threads = [threading.Thread(target=flood, args=(base, stop, codes, deadline))
                   for _ in range(args.flooders)]
        for t in threads:
            t.start()
        try:
            time.sleep(1.0)  # the flood is under way
            ms = participant(base, "FLOOD01")
        finally:
            stop.set()
            for t in threads:
                t.join()
        print(f"during a {args.flooders}-thread flood of bad tokens: {_summary(ms)}")
        print(f"flood responses: {dict(sorted(codes.items()))}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
