"""The > 3-feature geometry of one teaching round, old way against new, on a random domain.

    .venv/bin/python bench/bench_geometry_nd.py [--size 10x10] [--features 5]
        [--instances 1024] [--seed 0] [--lp-sets 200]

Builds the domain's demonstrations and the first round of `proposed` (8 uniform human
models from the prior, every demonstration's counterfactual rows), then prints CPU seconds
for:

* the knowledge gains of every demonstration as `teach` now computes them (one shared
  sample of the belief, `bec.gain_estimates`), and as before (each distinct intersection
  reduced and measured on its own: `geometry.intersection_areas`; its reduction now uses
  the least-squares test, so this row is already faster than before the change);
* reducing the first `--lp-sets` distinct demonstration row sets with the least-squares
  redundancy test against one `linprog` per row (the previous filter), and whether the two
  kept the same rows.

Figures are CPU time of this process (`time.process_time`), so other jobs on a shared
machine inflate them less than wall time, but they still do: quote ratios from one run.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from cfteach.bec import demo_set
from cfteach.bec.constraints import counterfactual_rows
from cfteach.bec.gain import gain_estimates
from cfteach.domains.random import random_gridworld
from cfteach.geometry import Region, clear_cache, intersection_areas
from cfteach.geometry._highdim import _lp_filter
from cfteach.teaching.sampling import sample_models


def lp_per_row(unit: np.ndarray) -> list[int]:
    """The previous filter, one LP per row over the current kept set (the tests' copy)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_geometry_highdim import _lp_reduce

    return _lp_reduce(unit)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", default="10x10")
    ap.add_argument("--features", type=int, default=5)
    ap.add_argument("--instances", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--lp-sets", type=int, default=200)
    args = ap.parse_args()
    w, h = (int(x) for x in args.size.split("x"))
    t = time.process_time()
    dom = random_gridworld(w, h, args.features, args.instances, args.seed)
    ds = demo_set(dom, "default")
    running = Region(np.asarray(dom.prior, dtype=np.int64), dim=ds.F)
    W = sample_models("default", running.reduced(), 8, np.random.default_rng([0, 1, 0]), ds.F)
    joint, _, _ = counterfactual_rows(ds, W, unbounded="loops")
    print(f"{w}x{h}, {args.features} features, {args.instances} instances: {ds.D} demos, "
          f"{joint.rows.shape[0]} rows; setup {time.process_time() - t:.1f} s CPU")

    clear_cache()
    t = time.process_time()
    gains, errors = gain_estimates(running, joint)
    new = time.process_time() - t
    live = gains > 1
    print(f"gains, shared sample:         {new:7.2f} s  ({int(live.sum())} demos gain > 1, "
          f"max {gains.max():.3f} +- {errors[np.argmax(gains)]:.3f})")

    clear_cache()
    ids = np.flatnonzero(joint.counts() > 0)
    sets, slot = joint.distinct(ids)
    t = time.process_time()
    areas = intersection_areas(running, sets)
    old = time.process_time() - t
    base = running.area()
    old_gains = np.where(areas > 0, base / np.where(areas > 0, areas, 1), 0.0)[slot]
    print(f"gains, one region per set:    {old:7.2f} s  ({len(sets)} distinct sets; max "
          f"{old_gains.max():.3f}; ratio {old / max(new, 1e-9):.1f}x)")

    pick = [s for s in sets if len(s) > 1][: args.lp_sets]
    units = [Region(s)._units() for s in pick]
    t = time.process_time()
    fast = [_lp_filter(u, np.arange(len(u))).tolist() for u in units]
    t_fast = time.process_time() - t
    t = time.process_time()
    slow = [lp_per_row(u) for u in units]
    t_slow = time.process_time() - t
    n_rows = sum(len(u) for u in units)
    same = sum(a == b for a, b in zip(fast, slow, strict=True))
    print(f"reduce {len(pick)} sets ({n_rows} rows): least squares {t_fast:.2f} s, "
          f"one LP per row {t_slow:.2f} s ({t_slow / max(t_fast, 1e-9):.0f}x); "
          f"same kept rows in {same}/{len(pick)}")


if __name__ == "__main__":
    main()
