"""`bench_closed_loop_study.py --suite`: every configuration the study's load targets name,
one after the other, each in a fresh `bench_closed_loop_study.py` process on one study
folder made once, then one table with the load average and the CPU split recorded per row.

First the server CPU per refused closed-loop answer (`--refusal-cost 300`), then the rows
(N = `-n`, default 200: half closed-loop, half open-loop; one event per `--pace` s):

1. SQLite, 1 server                          2. SQLite, 1 server, 2 attackers at their limits
3. SQLite, 1 server, the live teacher `--suite-teacher` (default n_particles=250) instead
   of the offline default (what a researcher may choose in the study file; docs/study.md)
4. SQLite, 2 servers, each session on one    5. SQLite, 2 servers, 2 attackers
   of them (`--sticky`)
6. PostgreSQL, 1 server                      7. PostgreSQL, 1 server, 2 attackers
8. PostgreSQL, 2 servers (round robin), N   9. PostgreSQL, 2 servers, sticky, N
10+. capacity: PostgreSQL with 1 and with 2 servers at N/2, then N/4, each only while the
    larger size missed (the largest N tested with every p99 < 500 ms is the capacity)

Rows 6+ need `--db postgresql+psycopg://...` (each run starts from an empty schema). The
attackers' effect is each database's attackers row against its row without them.
Each row runs about 90 to 150 s on an idle machine.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Targets (ms): decisions, every event, page reads; and the capacity threshold.
TARGETS = {"decision": 500.0, "event": 300.0, "page": 300.0}
CAPACITY_P99_MS = 500.0
#: Largest rise of the real participants' p99 that 2 attackers may cause.
ATTACK_RISE = 0.20
#: Capacity sizes tried below N, as shares of N (each only if the one before missed).
CAPACITY_SHARES = (0.5, 0.25)


#: Two servers, each participant on one of them (a proxy routing by session token).
_STICKY_PAIR = ["--servers", "2", "--decision-workers", "1", "--sticky"]


def _fixed_rows(args: argparse.Namespace) -> list[tuple[str, list[str]]]:
    n = str(args.participants)
    rows = [("sqlite", ["-n", n]),
            ("sqlite+attack", ["-n", n, "--attackers", "2"]),
            (f"sqlite, teacher {args.suite_teacher}", ["-n", n, "--teacher",
                                                       args.suite_teacher]),
            ("sqlite 2 servers", ["-n", n, *_STICKY_PAIR]),
            ("sqlite 2 servers+attack", ["-n", n, *_STICKY_PAIR, "--attackers", "2"])]
    if _pg(args):
        pg = ["--db", args.db]
        rows += [("pg", [*pg, "-n", n]),
                 ("pg+attack", [*pg, "-n", n, "--attackers", "2"]),
                 ("pg 2 servers", [*pg, "-n", n, "--servers", "2",
                                   "--decision-workers", "1"]),
                 ("pg 2 servers, sticky", [*pg, "-n", n, *_STICKY_PAIR])]
    return rows


def _pg(args: argparse.Namespace) -> bool:
    return bool(args.db and args.db.startswith("postgresql"))


def _capacity_ok(r: dict) -> bool:
    return "failed" not in r and r["ok"] and all(
        v is not None and v < CAPACITY_P99_MS for v in r["p99_ms"].values())


def run_suite(args: argparse.Namespace, script: Path) -> int:
    """Run every row; print the table and the targets' verdicts. 0 if every run stored
    every event exactly once (the latency targets are reported, not enforced)."""
    from bench_closed_loop_study import make_study

    tmp = Path(tempfile.mkdtemp(prefix="cfteach-cl-suite-"))
    study = args.study or make_study(tmp / "study", args)
    live = make_study(tmp / "study-live", argparse.Namespace(**{
        **vars(args), "teacher": ",".join(x for x in (args.teacher, args.suite_teacher) if x)}))
    common = ["--pace", str(args.pace), "--max-items", str(args.max_items),
              "--conditions", args.conditions, "--timeout", str(args.timeout)]
    results: dict[str, dict] = {}
    t0 = time.monotonic()
    print(f"\n== refused closed-loop answers (load average {os.getloadavg()[0]:.1f}) ==",
          flush=True)
    cost = subprocess.run([sys.executable, str(script), *common, "--study", str(study),
                           "--refusal-cost", "300"], check=False, capture_output=True, text=True)
    print(cost.stdout + cost.stderr[-2000:], flush=True)

    def run(name: str, extra: list[str]) -> dict:
        out = tmp / f"{name.replace(' ', '_').replace(',', '')}.json"
        folder = live if "--teacher" in extra else study
        print(f"\n== {name} (load average {os.getloadavg()[0]:.1f}) ==", flush=True)
        proc = subprocess.run([sys.executable, str(script), *common, "--study", str(folder),
                               *extra, "--json-out", str(out)], check=False)
        results[name] = (json.loads(out.read_text()) if out.exists()
                         else {"failed": proc.returncode})
        return results[name]

    for name, extra in _fixed_rows(args):
        run(name, extra)
    if _pg(args):
        for label, servers in (("pg", []), ("pg 2 servers", ["--servers", "2",
                                                             "--decision-workers", "1"])):
            last = results.get(label, {"failed": -1})
            for share in CAPACITY_SHARES:
                if _capacity_ok(last):
                    break
                n = max(2, int(round(args.participants * share)))
                last = run(f"{label} {n}", ["--db", args.db, "-n", str(n), *servers])
    print(f"\nsuite wall time {time.monotonic() - t0:.0f} s; {os.cpu_count()} cores")
    _table(results, args)
    print("\nserver CPU per refused answer (target < 10 ms for closed-loop answers):")
    for line in cost.stdout.splitlines():
        if "per refusal" in line or line.startswith("load average"):
            print(f"  {line}")
    return 0 if all(r.get("ok") for r in results.values()) else 1


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.0f}"


def _table(results: dict[str, dict], args: argparse.Namespace) -> None:
    print("\n| run | load start, end | participants | decision p99 ms | every event p99 "
          "ms | page p99 ms | cores: web server, decision workers, load generator | "
          "transport errors | lost / duplicated | targets |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, r in results.items():
        if "failed" in r:
            print(f"| {name} | - | - | - | - | - | - | - | run failed (exit {r['failed']}) "
                  "| - |")
            continue
        p = r["p99_ms"]
        met = all(p[k] is not None and p[k] < t for k, t in TARGETS.items()) and r["ok"]
        print(f"| {name} | {r['load_start']:.1f}, {r['load_end']:.1f} | {r['participants']} "
              f"| {_ms(p['decision'])} | {_ms(p['event'])} | {_ms(p['page'])} | "
              f"{r['web_cores']:.2f}, {r['worker_cores']:.2f}, {r['client_cores']:.2f} | "
              f"{r['transport_errors']} | {r['lost']} / {r['duplicated']} | "
              f"{'met' if met else 'missed'} |")
    for db in ("sqlite", "sqlite 2 servers", "pg"):
        base, hit = results.get(db), results.get(f"{db}+attack")
        if base and hit and "failed" not in base and "failed" not in hit:
            rises = {k: hit["p99_ms"][k] / base["p99_ms"][k] - 1 for k in TARGETS
                     if base["p99_ms"][k] and hit["p99_ms"][k] is not None}
            text = ", ".join(f"{k} {100 * v:+.0f}%" for k, v in rises.items())
            ok = all(v < ATTACK_RISE for v in rises.values())
            print(f"{db}: 2 attackers change real participants' p99 by {text} "
                  f"(target < +{100 * ATTACK_RISE:.0f}%: {'met' if ok else 'missed'})")
    for label, prefix in (("1 server", "pg"), ("2 servers", "pg 2 servers")):
        runs = [r for name, r in results.items() if "failed" not in r and (
            name == prefix or (name.startswith(prefix + " ") and name[len(prefix) + 1:]
                               .isdigit()))]
        if not runs:
            continue
        good = [r["participants"] for r in runs if _capacity_ok(r)]
        tested = ", ".join(str(r["participants"]) for r in runs)
        cap = (f"at least {max(good)}" if good else
               f"under {min(r['participants'] for r in runs)}")
        print(f"PostgreSQL capacity, {label} (every p99 < {CAPACITY_P99_MS:.0f} ms; "
              f"tested {tested}): {cap} participants")
