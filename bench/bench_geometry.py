"""Throughput of cfteach.geometry: Region.area()/reduced() at 10, 100, 1000 constraints,
and the teaching workload of ~25,000 small integer constraint sets.

Run: .venv/bin/python bench/bench_geometry.py   (prints a table; single core).
Times are CPU time of this process (time.process_time), so a busy machine inflates them
less than wall-clock time would.
"""

from __future__ import annotations

import time

import numpy as np

from cfteach.geometry import Region, clear_cache, reduce_many


def random_region_rows(rng: np.random.Generator, k: int) -> np.ndarray:
    """k float normals whose region is a non-empty polygon around a random direction."""
    centre = rng.standard_normal(3)
    centre /= np.linalg.norm(centre)
    n = rng.standard_normal((k, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    return n + rng.uniform(1.05, 2.0) * centre


def time_per_call(fn, inputs: list) -> float:
    t0 = time.process_time()
    for x in inputs:
        fn(x)
    return (time.process_time() - t0) / len(inputs)


def bench_sizes(rng: np.random.Generator) -> None:
    print("Region(normals).area() + .reduced(), float normals, cold cache (fresh sets)")
    print(f"{'k':>6} {'area ms':>10} {'reduced ms':>11} {'irredundant':>12}")
    for k in (10, 100, 1000):
        reps = 400 if k < 1000 else 100
        sets = [random_region_rows(rng, k) for _ in range(reps)]
        clear_cache()
        t_area = time_per_call(lambda s: Region(s).area(), sets)
        clear_cache()
        t_red = time_per_call(lambda s: Region(s).reduced(), sets)
        m = np.mean([len(Region(s).reduced()) for s in sets[:20]])
        print(f"{k:>6} {t_area * 1e3:>10.3f} {t_red * 1e3:>11.3f} {m:>12.1f}")
    print("integer normals (entries in [-6, 6]), cold cache")
    for k in (10, 100, 1000):
        reps = 400 if k < 1000 else 100
        sets = []
        for _ in range(reps):
            w = rng.standard_normal(3)
            base = rng.integers(-6, 7, size=(k, 3))
            s = np.sign(base @ w).astype(np.int64)
            s[s == 0] = 1
            sets.append(base * s[:, None])
        clear_cache()
        t_area = time_per_call(lambda s: Region(s).area(), sets)
        print(f"{k:>6} {t_area * 1e3:>10.3f} ms per area (reduced included)")


def teaching_workload(rng: np.random.Generator, n_sets: int = 25_000) -> list[np.ndarray]:
    """Small integer constraint sets like a teaching run's: 3-30 rows drawn with repetition
    from a pool of feature-count differences consistent with one true weight vector; about
    half the sets repeat an earlier one exactly."""
    w = np.array([0.4, -0.3, -0.87])
    pool = rng.integers(-4, 5, size=(400, 3))
    s = np.sign(pool @ w).astype(np.int64)
    pool = pool[s != 0] * s[s != 0, None]
    sets: list[np.ndarray] = []
    for _ in range(n_sets):
        if sets and rng.random() < 0.5:
            sets.append(sets[int(rng.integers(len(sets)))].copy())
            continue
        k = int(rng.integers(3, 31))
        base = pool[rng.integers(0, 40, size=k)]  # 40 common rows -> many duplicates
        sets.append(base)
    return sets


def bench_many(rng: np.random.Generator) -> None:
    sets = teaching_workload(rng)
    distinct = len({(a.shape, a.tobytes()) for a in sets})
    clear_cache()
    t0 = time.process_time()
    red, areas = reduce_many(sets)
    dt = time.process_time() - t0
    print(f"\nreduce_many on {len(sets)} small integer sets ({distinct} distinct inputs):")
    print(f"  total {dt:.2f} s, {dt / len(sets) * 1e6:.0f} us per set (cold cache)")
    clear_cache()
    uniq = list({(a.shape, a.tobytes()): a for a in sets}.values())
    t0 = time.process_time()
    for a in uniq:
        r = Region(a)
        r.reduced()
        r.area()
    dt = time.process_time() - t0
    print(f"  distinct sets alone, no cache hits: {dt / len(uniq) * 1e6:.0f} us per set")
    print(f"  mean irredundant rows {np.mean([len(r) for r in red]):.2f}, "
          f"empty {int(np.sum(areas == 0))}")


def bench_reference_grid() -> None:
    """The reference's grid sampler: dominated by testing 10^6 coarse-grid points."""
    from cfteach.geometry import sample_reference_grid

    sample_reference_grid([[0, 0, -1]], 8)  # builds the cached coarse grid
    cases = {"prior [[0, 0, -1]]": [[0, 0, -1]],
             "delivery's BEC (3 rows)": [[1, 1, 0], [0, -1, -4], [-1, 0, 2]]}
    print("\nsample_reference_grid(m=8), coarse grid cached")
    for label, rows in cases.items():
        t = time_per_call(lambda r: sample_reference_grid(r, 8), [rows] * 5)
        print(f"  {label:<26} {t * 1e3:8.1f} ms per call")


def main() -> None:
    rng = np.random.default_rng(0)
    Region(np.eye(3)).area()  # warm imports
    bench_sizes(rng)
    bench_many(rng)
    bench_reference_grid()


if __name__ == "__main__":
    main()
