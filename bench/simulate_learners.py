"""Time the simulated learners' planning: teach + answer for blocks of learners.

Teaching material (curriculum + tests, `cfteach.teaching`, not timed) is made once per
domain; then for each learner model a block of `--learners` learners is taught the
`proposed` curriculum and answers the tests, `--reps` times. Prints the best and median
seconds per block (best = least disturbed by other load). Run it against another source tree
with PYTHONPATH=<tree>/src to compare versions on the same machine.

    .venv/bin/python bench/simulate_learners.py [--learners 32] [--reps 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domains", default="skateboard,delivery")
    ap.add_argument("--models", default="counterfactual,irl,noisy")
    ap.add_argument("--learners", type=int, default=32)
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args()

    import cfteach
    from cfteach import teaching
    from cfteach.domains import load
    from cfteach.simulate.learners import Learners
    from cfteach.simulate.sweep import answer_items

    print(f"cfteach from {cfteach.__file__}")
    for name in args.domains.split(","):
        dom = load(name)
        cur = teaching.teach(dom, "proposed", seed=0)
        test_set = teaching.select_tests(dom, training=(cur,), seed=0).to_json()
        tests = answer_items(test_set, False)
        demos = cur.to_json()["demos"]
        for model in args.models.split(","):
            times = []
            for rep in range(args.reps):
                t0 = time.perf_counter()
                learners = Learners(dom, model, args.learners, rng=np.random.default_rng(rep))
                learners.teach(demos)
                ans = learners.answer(tests)
                times.append(time.perf_counter() - t0)
            print(f"{name:11s} {model:15s} {args.learners} learners, {len(demos)} demos, "
                  f"{len(tests)} tests: best {min(times):.3f} s, median "
                  f"{statistics.median(times):.3f} s per block "
                  f"(proportion correct {ans['correct'].mean():.2f})")


if __name__ == "__main__":
    main()
