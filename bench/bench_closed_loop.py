"""Closed-loop teaching latency: one `teacher.next()` + `teacher.observe()` on the paper's
domains, over whole simulated sessions (the study server decides while the participant
watches, so p99 must stay well under a second; target < 300 ms).

Per domain: build the lesson pool once (timed separately: the server does it at start-up;
with `proposed`'s curriculum as its backbone, as the simulation's teacher has),
then run `--sessions` sessions with simulated learners and time every decision and update
(the learner's own thinking is not timed).

    .venv/bin/python bench/bench_closed_loop.py
    .venv/bin/python bench/bench_closed_loop.py --domains delivery --sessions 3 --learner noisy
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domains", default="delivery,tiles,skateboard")
    ap.add_argument("--sessions", type=int, default=5)
    ap.add_argument("--learner", default="inattentive")
    ap.add_argument("--no-backbone", action="store_true",
                    help="build the pool without proposed's curriculum as its backbone")
    ap.add_argument("--teacher", default="",
                    help="TeacherSettings as field=value,... (e.g. model=fixed)")
    args = ap.parse_args()

    from cfteach import teaching
    from cfteach.cli.simulate_cmd import _teacher_settings
    from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, build_pool
    from cfteach.domains import load
    from cfteach.simulate.learners import Learners

    print(f"{'domain':12s} {'pool s':>7s} {'steps':>6s} {'p50 ms':>8s} {'p99 ms':>8s} "
          f"{'max ms':>8s} {'items/session':>14s}")
    for name in args.domains.split(","):
        dom = load(name)
        t0 = time.perf_counter()
        cur = teaching.teach(dom, "proposed")
        tests = teaching.select_tests(dom, training=[cur])
        pool = build_pool(dom, held_out=tests,
                          backbone=None if args.no_backbone else cur.to_json()["demos"])
        t_pool = time.perf_counter() - t0
        times, items = [], []
        for s in range(args.sessions):
            settings = TeacherSettings(**_teacher_settings(
                [p for p in args.teacher.split(",") if p]))
            teacher = ClosedLoopTeacher(pool, settings, seed=s)
            learner = Learners(dom, args.learner, 1, rng=1000 + s)
            while True:
                t = time.perf_counter()
                item = teacher.next()
                dt = time.perf_counter() - t
                if item is None:
                    times.append(dt)
                    break
                shown = item.to_json(pool)
                if item.kind == "test":  # the moves, as the study server sends them
                    ans = learner.answer([shown], moves=True)
                    resp = {"actions": ans["actions"][0][0]}
                else:
                    learner.observe(shown)
                    resp = {}
                t = time.perf_counter()
                teacher.observe(resp)
                times.append(dt + time.perf_counter() - t)
            items.append(len(teacher.items))
        ms = np.array(times) * 1000
        print(f"{name:12s} {t_pool:7.1f} {len(ms):6d} {np.percentile(ms, 50):8.1f} "
              f"{np.percentile(ms, 99):8.1f} {ms.max():8.1f} {np.mean(items):14.1f}")


if __name__ == "__main__":
    main()
