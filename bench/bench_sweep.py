"""Scale-out benchmark: the teaching stage's expensive core on a large random domain.

Work: for every instance of a random gridworld (default 10x10, 5 features, 4096 instances)
and every one of M sampled human models (default 64): exact value iteration, then the
"benefit of the doubt" counterfactual from every state (cfteach.mdp.best_tied_trajectories)
and its constraint mu(robot) - mu(human). This is what one round of counterfactual
teaching / test selection computes. The instances are cut into coarse chunks and run through
cfteach.parallel on 1 local worker, N local workers and a local Dask cluster; the script
prints wall times, throughput, the scaling ratio, and checks that every backend returned
identical results.

    .venv/bin/python bench/bench_sweep.py                       # the full-size sweep
    .venv/bin/python bench/bench_sweep.py --instances 256 --models 16   # a quick look
"""

from __future__ import annotations

import argparse
import hashlib
import os
import time

import numpy as np


def _chunk_work(chunk: dict) -> dict:
    """One chunk of instances: plan for every human model, form the constraints."""
    from cfteach.mdp import best_tied_trajectories, compile_instances, value_iteration
    from cfteach.simulate.sweep import load_domain  # cached per worker process

    cpu0 = time.process_time()
    dom = load_domain(("random", *chunk["domain"]))
    insts = dom.instances()[chunk["start"]:chunk["stop"]]
    batch = compile_instances(insts)
    W = np.asarray(chunk["W"])
    human = value_iteration(batch, W)
    robot = value_iteration(batch, dom.weights[None])
    best = best_tied_trajectories(batch, human.Q, dom.weights, horizon=chunk["horizon"])
    robot_best = best_tied_trajectories(batch, robot.Q, dom.weights, horizon=chunk["horizon"])
    mu_robot = robot_best.mu[:, 0]                                 # [E, S, F]
    cons = mu_robot[:, None] - best.mu                             # [E, M, S, F]
    ok = human.bounded[:, :, None] & batch.valid[:, None, :] & np.isfinite(best.value)
    informative = ok & np.any(cons != 0, axis=-1)
    digest = hashlib.sha256(np.where(ok[..., None], cons, 0).astype(np.int64).tobytes())
    return {"pairs": int(batch.E * W.shape[0]), "states": int(batch.valid.sum()),
            "bounded": int(human.bounded.sum()), "informative": int(informative.sum()),
            "digest": digest.hexdigest(), "cpu": time.process_time() - cpu0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--width", type=int, default=10)
    ap.add_argument("--height", type=int, default=10)
    ap.add_argument("--features", type=int, default=5)
    ap.add_argument("--instances", type=int, default=4096)
    ap.add_argument("--models", type=int, default=64)
    ap.add_argument("--chunk", type=int, default=128, help="instances per chunk")
    ap.add_argument("--horizon", type=int, default=25)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                    help="workers for the parallel runs")
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    from cfteach.domains.random import random_gridworld
    from cfteach.geometry import Region
    from cfteach.parallel import Executor, chunk_slices

    spec = (args.width, args.height, args.features, args.instances, args.seed)
    dom = random_gridworld(*spec)
    W = Region(np.asarray(dom.prior), dim=dom.n_features).sample(
        args.models, np.random.default_rng(args.seed))
    chunks = [{"domain": spec, "start": s.start, "stop": s.stop, "W": W,
               "horizon": args.horizon}
              for s in chunk_slices(args.instances, chunk_size=args.chunk)]
    print(f"domain {dom.name}: {args.instances} instances x {args.models} human models, "
          f"{len(chunks)} chunks of <= {args.chunk} instances; {os.cpu_count()} cores here")

    runs = [("local, 1 worker", {"n_workers": 1}),
            (f"local, {args.workers} workers", {"n_workers": args.workers})]
    if not args.no_dask:
        runs.append((f"dask LocalCluster, {args.workers} workers",
                     {"backend": "dask", "n_workers": args.workers}))
    results, times = {}, {}
    for label, cfg in runs:
        with Executor(**cfg) as ex:
            if cfg.get("backend") == "dask" or cfg["n_workers"] > 1:
                ex.map(_chunk_work, chunks[:cfg["n_workers"]])   # warm the workers up
            t0 = time.perf_counter()
            out = ex.map(_chunk_work, chunks, progress=True, desc=label)
            times[label] = time.perf_counter() - t0
        results[label] = out
        pairs = sum(o["pairs"] for o in out)
        cpu = sum(o["cpu"] for o in out)
        print(f"{label:34s} wall {times[label]:8.2f} s  {pairs / times[label]:8.0f} pairs/s  "
              f"worker CPU {cpu:8.2f} s  informative constraints: "
              f"{sum(o['informative'] for o in out)}")
    base = runs[0][0]
    for label, _ in runs[1:]:
        same = [o["digest"] for o in results[label]] == [o["digest"] for o in results[base]]
        print(f"speed-up {label} vs {base}: {times[base] / times[label]:.2f}x; "
              f"identical results: {same}")
    print("(workers warmed up before timing; wall times depend on the machine's other load, "
          "worker CPU time much less so)")


if __name__ == "__main__":
    main()
