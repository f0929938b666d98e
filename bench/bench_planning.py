"""Throughput of batched planning: value iteration and greedy rollouts from every state.

For each built-in domain: every instance x 1000 weight vectors drawn uniformly from the unit
sphere (half of them with a positive step weight, so many pairs are unbounded), solved in
chunks of weight vectors to bound memory; then greedy rollouts from every state (plain and
with every forced first action, as the one-action-deviation constraints need) for 8 models.

    .venv/bin/python bench/bench_planning.py [--models 1000] [--chunk 100] [--reference 50]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from cfteach.domains import builtin_names, load
from cfteach.mdp import compile_domain, greedy_actions, rollout_features, value_iteration


def clock() -> float:
    """CPU seconds of this process: stable when other jobs share the machine."""
    return time.process_time()


def sphere(m: int, f: int, rng: np.random.Generator) -> np.ndarray:
    w = rng.normal(size=(m, f))
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=int, default=1000, help="weight vectors per domain")
    ap.add_argument("--chunk", type=int, default=100, help="weight vectors per VI call")
    ap.add_argument("--reference", type=int, default=50,
                    help="weight vectors (drawn from the prior w_step <= 0) for the "
                         "reference method, which runs 1000 sweeps on unbounded pairs")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    print(f"# {os.cpu_count()} CPUs, single process; seconds = CPU time of this process")
    print(f"{'domain':<11} {'what':<44} {'pairs':>8} {'seconds':>8} {'pairs/s':>10}")
    for name in builtin_names():
        dom = load(name)
        t = clock()
        b = compile_domain(dom)
        t_compile = clock() - t
        label = f"compile (E={b.E}, S={b.S})"
        print(f"{name:<11} {label:<44} {b.E:>8} {t_compile:>8.2f}")
        W = sphere(args.models, b.F, rng)
        t = clock()
        n_bounded = 0
        for i in range(0, len(W), args.chunk):
            vals = value_iteration(b, W[i:i + args.chunk])
            n_bounded += int(vals.bounded.sum())
            del vals
        dt = clock() - t
        pairs = b.E * len(W)
        label = f"VI exact, sphere ({100 * n_bounded / pairs:.0f}% bounded)"
        print(f"{name:<11} {label:<44} {pairs:>8} {dt:>8.2f} {pairs / dt:>10.0f}")

        Wp = sphere(args.reference, b.F, rng)
        Wp[:, -1] = -np.abs(Wp[:, -1])
        for method in ("exact", "reference"):
            t = clock()
            vals = value_iteration(b, Wp, method=method)
            dt = clock() - t
            pairs = b.E * len(Wp)
            label = f"VI {method}, prior (w_step<=0, {100 * vals.bounded.mean():.0f}% bounded)"
            print(f"{name:<11} {label:<44} {pairs:>8} {dt:>8.2f} {pairs / dt:>10.0f}")

        W8 = np.vstack([dom.weights, Wp[:7]])
        pol = greedy_actions(value_iteration(b, W8, method="reference").Q)
        starts = int(b.n_states.sum()) * len(W8)
        t = clock()
        rollout_features(b, pol, return_paths=True)
        dt = clock() - t
        print(f"{name:<11} {'greedy rollouts from every state, 8 models':<44} {starts:>8} "
              f"{dt:>8.2f} {starts / dt:>10.0f}")
        t = clock()
        rollout_features(b, pol, first_action="all")
        dt = clock() - t
        n = starts * b.A
        print(f"{name:<11} {'  ... with every forced first action':<44} {n:>8} {dt:>8.2f} "
              f"{n / dt:>10.0f}")


if __name__ == "__main__":
    main()
