"""Memory cost of oversized request bodies without a Content-Length (chunked transfer).

Starts `cfteach serve` on 127.0.0.1 (a toy study, throw-away SQLite file), then for each
size streams one chunked body of that size to /api/event and prints the HTTP status and the
rise of the server process's peak resident set size (VmHWM, Linux). The server refuses a
body as soon as it passes 64 KiB, so the rise should stay near zero whatever the size.

    .venv/bin/python bench/bench_body_limit.py              # 40 MB
    .venv/bin/python bench/bench_body_limit.py --mb 1 40 300
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from cfteach.study.build import init_study, toy_sources
from cfteach.study.livesrv import serving_process
from cfteach.study.probe import peak_rss_mb, post_chunked

MAX_MB = 1000


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, nargs="+", default=[40.0],
                    help="body sizes in MiB, one request each (at most 1000)")
    args = ap.parse_args()
    if not all(0 < mb <= MAX_MB for mb in args.mb):
        ap.error(f"--mb must be in (0, {MAX_MB}]")
    tmp = Path(tempfile.mkdtemp(prefix="cfteach-body-"))
    init_study(tmp / "study", toy_sources())
    with serving_process(tmp / "study", "--db", f"sqlite:///{tmp / 'b.db'}") as (base, proc):
        port = int(base.rsplit(":", 1)[1])
        for mb in args.mb:
            before = peak_rss_mb(proc.pid)
            t0 = time.perf_counter()
            r = post_chunked("127.0.0.1", port, "/api/event", int(mb * 1024 * 1024),
                             timeout=300)
            dt = time.perf_counter() - t0
            after = peak_rss_mb(proc.pid)
            print(f"chunked body {mb:g} MiB: HTTP {r.status or 'no answer'} after "
                  f"{r.sent / 1024 / 1024:.1f} MiB sent, {dt:.2f} s; server peak RSS "
                  f"{before:.0f} -> {after:.0f} MiB (+{after - before:.1f} MiB)")
            if proc.poll() is not None:
                print("the server died")
                return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
