"""Cost of building a domain's arrays: the vectorised search against one state at a time.

For each domain: `compile_instances` (one vectorised breadth-first search over every instance,
`cfteach.domains.dynamics`) against the plain-Python, one-state-at-a-time BFS that the test
suite keeps as its independent reference (`tests/test_domains_compile.py`; it steps like the
code before the vectorised search: every transition computed in the search and again for the
table). Then the whole `cfteach.bec.demos.demo_set` of the 10 x 10, 5-feature, 1,024-instance
random domain (compile, checks, planning, rollouts), and this process's peak RSS.

    .venv/bin/python bench/bench_compile.py [--skip-reference] [--instances 1024]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from cfteach.bec.demos import demo_set  # noqa: E402
from cfteach.domains import load, random_gridworld  # noqa: E402
from cfteach.mdp import compile_instances  # noqa: E402


def clock() -> float:
    """CPU seconds of this process: stable when other jobs share the machine."""
    return time.process_time()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-reference", action="store_true",
                    help="do not time the one-state-at-a-time reference (slow)")
    ap.add_argument("--instances", type=int, default=1024,
                    help="instances of the 10 x 10, 5-feature random domain")
    args = ap.parse_args()
    from test_domains_compile import ref_compile

    doms = [load(n) for n in ("delivery", "tiles", "skateboard")]
    doms.append(load(ROOT / "examples" / "domains" / "augmented_taxi_2021.toml"))
    doms.append(random_gridworld(10, 10, 5, args.instances, 0))
    print(f"{'domain':<28} {'instances':>9} {'states':>8} {'compile s':>10} "
          f"{'reference s':>12} {'ratio':>7}")
    for dom in doms:
        insts = dom.instances()
        t = clock()
        batch = compile_instances(insts)
        fast = clock() - t
        ref = float("nan")
        if not args.skip_reference:
            fresh = type(dom).from_spec(dom.spec).instances()  # no cached states
            t = clock()
            for inst in fresh:
                ref_compile(inst)
            ref = clock() - t
        print(f"{dom.name:<28} {len(insts):>9} {int(batch.n_states.sum()):>8} {fast:>10.3f} "
              f"{ref:>12.3f} {ref / fast:>6.0f}x")
    dom = random_gridworld(10, 10, 5, args.instances, 0)
    t0, w0 = clock(), time.perf_counter()
    demo_set(dom, "default")
    print(f"demo_set(random_gridworld(10, 10, 5, {args.instances}, 0)): "
          f"{clock() - t0:.2f} s CPU, {time.perf_counter() - w0:.2f} s wall")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS of this process: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
