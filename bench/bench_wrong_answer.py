"""Does a wrong answer lower the closed-loop teacher's predicted success? Over many sessions.

The learner model must read a noisy learner's mistake as evidence of noise, not of skill:
after a wrong answer the teacher's predicted P(optimal) on its own probes should fall, on
average, in every domain. `tests/test_closedloop_noisy.py` checks this on 10 sessions per
domain; a mean over 10 sessions of changes whose spread is about 0.15 has a standard error
near 0.015, too coarse to rank teacher settings whose means differ by 0.02. This runs more
sessions per domain and prints the mean change with its standard error, so settings can be
compared (and a default chosen) on figures that are not noise.

    .venv/bin/python bench/bench_wrong_answer.py
    .venv/bin/python bench/bench_wrong_answer.py --sessions 30 \
        --teacher confused=0/0.25/0.5/0.75,lapse=0.002
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domains", default="delivery,skateboard,tiles")
    ap.add_argument("--sessions", type=int, default=30)
    ap.add_argument("--learner", default="noisy")
    ap.add_argument("--teacher", default="",
                    help="TeacherSettings as field=value,... (grids as a/b/c)")
    args = ap.parse_args()

    from cfteach.cli.simulate_cmd import _teacher_settings
    from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, build_pool
    from cfteach.simulate.learners import Learners

    # The test's setting (300 particles, 20 items), with the given settings over it.
    base = {"n_particles": 300, "max_items": 20}
    settings = TeacherSettings(**{**base, **_teacher_settings(
        [p for p in args.teacher.split(",") if p])})
    print(f"teacher: {args.teacher or 'defaults'}; learner {args.learner}; "
          f"{args.sessions} sessions per domain")
    print(f"{'domain':12s} {'wrong':>6s} {'mean change':>12s} {'s.e.':>7s} "
          f"{'share > 0':>10s} {'s':>5s}")
    for domain in args.domains.split(","):
        t0 = time.perf_counter()
        pool = build_pool(domain, human_models=8, held_out=[])
        changes = []
        for seed in range(args.sessions):
            teacher = ClosedLoopTeacher(pool, settings, seed=seed)
            learner = Learners(pool.domain, args.learner, 1, rng=seed)
            while (item := teacher.next()) is not None:
                shown = item.to_json(pool)
                if item.kind != "test":
                    learner.observe(shown)
                    teacher.observe({})
                    continue
                before = teacher.prediction()["predicted"]
                ans = learner.answer([shown], moves=True)
                teacher.observe({"actions": ans["actions"][0][0]})
                if not teacher.outcomes[item.index].correct:
                    changes.append(teacher.prediction()["predicted"] - before)
        c = np.array(changes)
        se = c.std(ddof=1) / np.sqrt(len(c)) if len(c) > 1 else float("nan")
        print(f"{domain:12s} {len(c):6d} {c.mean() if len(c) else float('nan'):+12.4f} "
              f"{se:7.4f} {(c > 0).mean() if len(c) else float('nan'):10.2f} "
              f"{time.perf_counter() - t0:5.0f}")


if __name__ == "__main__":
    main()
