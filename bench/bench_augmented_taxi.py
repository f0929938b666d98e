"""Time to compute every one-step constraint set of the 2021 augmented taxi (256 instances,
25,600 demonstrations; issue target: under 5 s), and its policy-level BEC.

    .venv/bin/python bench/bench_augmented_taxi.py
"""

from __future__ import annotations

import resource
import time
from pathlib import Path

from cfteach.bec import policy_bec
from cfteach.bec.demos import demo_set
from cfteach.domains import load
from cfteach.teaching.common import one_step_sets

TAXI = Path(__file__).resolve().parents[1] / "examples" / "domains" / "augmented_taxi_2021.toml"


def main() -> None:
    w0, c0 = time.perf_counter(), time.process_time()
    dom = load(TAXI)
    ds = demo_set(dom, "default")
    sets = one_step_sets(ds)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    print(f"{dom.name}: {len(dom.instances())} instances, {ds.D} demonstrations, "
          f"{len(sets)} one-step constraint sets in {wall:.2f} s wall ({cpu:.2f} s CPU), "
          "load and planning included")
    w0 = time.perf_counter()
    bec = policy_bec(dom)
    print(f"policy-level BEC ({time.perf_counter() - w0:.2f} s): {bec.tolist()}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS of this process: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
