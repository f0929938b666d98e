"""Record whole closed-loop sessions and compare two recordings bit for bit: a speed change
to the teacher or its belief must leave every item, particle, weight and grid index as it
was (docs/closed-loop.md, "Speed"). With `--tolerance T` floating-point values need only
agree within T (absolute and relative), for a change that reorders arithmetic; items, stop
reasons, grid indices and every other non-float value must still be equal.

    .venv/bin/python bench/closed_loop_identity.py record before.pkl
    ...change the code...
    .venv/bin/python bench/closed_loop_identity.py record after.pkl
    .venv/bin/python bench/closed_loop_identity.py compare before.pkl after.pkl
    .venv/bin/python bench/closed_loop_identity.py compare --tolerance 1e-9 before.pkl after.pkl

Sessions: every domain of `--domains` x learner kind of `--learners` x `--seeds` teacher
seeds, on a pool with `proposed`'s curriculum as its backbone (as the simulation's);
`--teacher field=value,...` passes TeacherSettings.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from typing import Any

import numpy as np


def record(args: argparse.Namespace) -> dict[str, Any]:
    from cfteach import teaching
    from cfteach.cli.simulate_cmd import _teacher_settings
    from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, build_pool
    from cfteach.domains import load
    from cfteach.simulate.learners import Learners

    out: dict[str, Any] = {}
    settings = TeacherSettings(**_teacher_settings([p for p in args.teacher.split(",") if p]))
    for name in args.domains.split(","):
        dom = load(name)
        cur = teaching.teach(dom, "proposed")
        tests = teaching.select_tests(dom, training=[cur])
        pool = build_pool(dom, held_out=tests, backbone=cur.to_json()["demos"])
        for kind in args.learners.split(","):
            for s in range(args.seeds):
                teacher = ClosedLoopTeacher(pool, settings, seed=s)
                learner = Learners(dom, kind, 1, rng=1000 + s)
                while (item := teacher.next()) is not None:
                    shown = item.to_json(pool)
                    if item.kind == "test":
                        ans = learner.answer([shown], moves=True)
                        resp = {"actions": ans["actions"][0][0]}
                    else:
                        learner.observe(shown)
                        resp = {}
                    teacher.observe(resp)
                b = teacher.belief
                out[f"{name}/{kind}/{s}"] = {
                    "items": [it.to_json(pool) for it in teacher.items],
                    "stop": teacher.stop_reason,
                    "particles": b.particles.copy(), "log_weights": b.log_weights.copy(),
                    # A grid of one value carries no information (its index is 0 everywhere),
                    # so a new grid that is off compares equal to its absence.
                    "idx": {k: v.copy() for k, v in getattr(b, "idx", {}).items()
                            if len(b.grids[k]) > 1},
                    "responses": teacher.responses}
                print(f"{name}/{kind}/{s}: {len(teacher.items)} items", flush=True)
    return out


def _same(a: Any, b: Any, tol: float = 0.0) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape or a.dtype != b.dtype:
            return False
        if tol and a.dtype.kind == "f":
            return bool(np.allclose(a, b, rtol=tol, atol=tol, equal_nan=True))
        return a.tobytes() == b.tobytes()
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k], tol) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same(x, y, tol) for x, y in zip(a, b, strict=True))
    if tol and isinstance(a, float) and isinstance(b, float):
        return abs(a - b) <= tol * (1 + abs(b))
    return bool(a == b)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=["record", "compare"])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--domains", default="delivery,skateboard,tiles")
    ap.add_argument("--learners", default="inattentive,noisy")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--teacher", default="")
    ap.add_argument("--tolerance", type=float, default=0.0,
                    help="compare: floats within this (absolute and relative); 0 = bit for bit")
    args = ap.parse_args()
    if args.mode == "record":
        with open(args.files[0], "wb") as fh:
            pickle.dump(record(args), fh)
        return
    if len(args.files) != 2:
        sys.exit("compare: give two recordings")
    a, b = (pickle.load(open(f, "rb")) for f in args.files)  # noqa: SIM115
    bad = [k for k in sorted(set(a) | set(b))
           if k not in a or k not in b or not _same(a[k], b[k], args.tolerance)]
    print(f"{len(a)} and {len(b)} sessions; {len(bad)} differ" + (f": {bad}" if bad else ""))
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
