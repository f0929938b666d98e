"""Time the whole teaching job: 3 domains x 4 conditions + test selection, per stage.

    .venv/bin/python bench/bench_teaching.py [--profile default|reference|both]

Runs in a fresh process (no warm caches) and prints seconds per stage and the total.
"""

from __future__ import annotations

import argparse
import time

from cfteach.bec import demo_set
from cfteach.bec.constraints import one_action_rows
from cfteach.domains import load
from cfteach.teaching import CONDITIONS, select_tests, teach
from cfteach.teaching.common import one_step_sets


def run(profile: str) -> float:
    total = 0.0
    print(f"profile {profile}")
    print(f"{'domain':<11}{'stage':<22}{'seconds':>8}  result")
    for name in ("delivery", "tiles", "skateboard"):
        t = time.perf_counter()
        dom = load(name)
        ds = demo_set(dom, profile)
        one_step_sets(ds)
        one_action_rows(ds, first_step_only=True)
        dt = time.perf_counter() - t
        total += dt
        print(f"{name:<11}{'demos + one-step sets':<22}{dt:8.2f}  {ds.D} demonstrations")
        curricula = []
        for cond in CONDITIONS:
            t = time.perf_counter()
            cur = teach(dom, cond, profile=profile)
            dt = time.perf_counter() - t
            total += dt
            curricula.append(cur)
            print(f"{name:<11}{cond:<22}{dt:8.2f}  {len(cur)} demos, final area "
                  f"{cur.final_belief.area():.5f}")
        t = time.perf_counter()
        ts = select_tests(dom, training=curricula, profile=profile)
        dt = time.perf_counter() - t
        total += dt
        sizes = {k: len(v) for k, v in ts.tests.items()}
        print(f"{name:<11}{'tests':<22}{dt:8.2f}  {sizes}")
    print(f"total {total:.1f} s ({profile})\n")
    return total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", choices=("default", "reference", "both"), default="both")
    args = ap.parse_args()
    profiles = ("default", "reference") if args.profile == "both" else (args.profile,)
    for p in profiles:
        run(p)


if __name__ == "__main__":
    main()
