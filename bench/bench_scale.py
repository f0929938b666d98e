"""Teaching at scale: time and peak memory of `proposed` on random gridworlds.

Each run is `teach(random_gridworld(W, H, F, N, 0), "proposed", profile="default", seed=0,
workers=K)` in a fresh Python process (so caches and memory start empty); peak RSS is
sampled every 0.1 s over that process and its worker processes (main, and main + workers).
The Dask run uses a `distributed.LocalCluster` and checks that it picks the same
demonstrations (bit-identical curriculum JSON) as the one-process run.

    .venv/bin/python bench/bench_scale.py                  # all sizes, 1 and 2 workers
    .venv/bin/python bench/bench_scale.py --sizes 8x8f4:16,8x8f4:64 --workers 1,2
    .venv/bin/python bench/bench_scale.py --sizes 10x10f5:1024 --dask --json out.json
    .venv/bin/python bench/bench_scale.py --profile        # where the time goes (1 process)

`--json FILE` keeps the figures for `bench/plot_scale.py` (the picture in docs/parallel.md).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

DEFAULT_SIZES = "8x8f4:16,8x8f4:64,8x8f4:256,10x10f5:1024,10x10f5:4096"


def _parse_size(text: str) -> tuple[int, int, int, int]:
    grid, n = text.split(":")
    wh, f = grid.split("f")
    w, h = wh.split("x")
    return int(w), int(h), int(f), int(n)


class _PeakRSS:
    """Samples the RSS of this process and of all its descendants (the workers)."""

    def __init__(self) -> None:
        import psutil

        self.proc = psutil.Process()
        self.main = self.total = 0
        self.cpu: dict[int, float] = {}  # user + system seconds of each process seen
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        import psutil

        while not self._stop.is_set():
            try:
                main = self.proc.memory_info().rss
                self._cpu(self.proc)
                kids = 0
                for c in self.proc.children(recursive=True):
                    try:
                        kids += c.memory_info().rss
                        self._cpu(c)
                    except psutil.Error:
                        pass
                self.main, self.total = max(self.main, main), max(self.total, main + kids)
            except psutil.Error:
                pass
            self._stop.wait(0.1)

    def _cpu(self, p) -> None:
        t = p.cpu_times()
        self.cpu[p.pid] = t.user + t.system

    @property
    def cpu_seconds(self) -> float:
        """CPU time of this process and its workers (sampled; short-lived ones may be missed)."""
        self._cpu(self.proc)
        return sum(self.cpu.values())

    def __enter__(self) -> _PeakRSS:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def one_run(size: str, workers: int, backend: str) -> dict:
    """Teach once in this process; the figures as a dict."""
    from cfteach.domains import random_gridworld
    from cfteach.teaching import teach

    w, h, f, n = _parse_size(size)
    with _PeakRSS() as rss:
        t0 = time.perf_counter()
        dom = random_gridworld(w, h, f, n, 0)
        cur = teach(dom, "proposed", profile="default", seed=0, backend=backend,
                    workers=workers)
        seconds = time.perf_counter() - t0
    data = cur.to_json()
    picks = [d["env_index"] for d in data["demos"]], [d["start_state"] for d in data["demos"]]
    digest = hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]
    return {"size": size, "instances": n, "workers": workers, "backend": backend,
            "seconds": round(seconds, 2), "cpu_seconds": round(rss.cpu_seconds, 1),
            "peak_rss_main_mb": round(rss.main / 2**20),
            "peak_rss_total_mb": round(rss.total / 2**20), "picks": picks, "digest": digest,
            "load_avg_1min": round(os.getloadavg()[0], 2)}


def profile_run(size: str, top: int) -> None:
    """cProfile one single-process run and print the teaching stages' cumulative times."""
    import cProfile
    import pstats

    from cfteach.domains import random_gridworld
    from cfteach.teaching import teach

    w, h, f, n = _parse_size(size)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    teach(random_gridworld(w, h, f, n, 0), "proposed", profile="default", seed=0)
    prof.disable()
    print(f"{size}: {time.perf_counter() - t0:.1f} s under cProfile")
    stats = pstats.Stats(prof)
    stages = {
        "demo_set (compile + true-reward planning)": "demos.py:_build",
        "  domain compile (Domain.step per state)": "arrays.py:compile_instances",
        "one-step constraint sets (masking order)": "common.py:one_step_sets",
        "counterfactual rows (all chunks)": "constraints.py:counterfactual_rowset",
        "  human-model planning (VI + best tied mu)": "constraints.py:human_mu_batch",
        "knowledge gains (estimates and their errors)": "gain.py:gain_estimates",
        "  shared-sample fractions (> 3 features)": "region.py:intersection_fractions",
        "  refining the contenders (refine_top)": "gain.py:refine_top",
        "feature-mask checks (blocked)": "counterfactual.py:blocked",
        "> 3-feature volume estimates (area_nd)": "_highdim.py:area_nd",
        "redundancy filter (_lp_filter)": "_highdim.py:_lp_filter",
        "tie-breaks (visual simplicity)": "visual.py:tie_break",
    }
    cum: dict[str, float] = {}
    for (file, _line, func), row in stats.stats.items():  # type: ignore[attr-defined]
        key = f"{Path(file).name}:{func}"
        cum[key] = max(cum.get(key, 0.0), row[3])
    for label, key in stages.items():
        print(f"  {label:<45} {cum.get(key, 0.0):8.1f} s")
    stats.sort_stats("cumulative").print_stats(top)


def _child(size: str, workers: int, backend: str) -> dict:
    cmd = [sys.executable, __file__, "--one", size, "--one-workers", str(workers),
           "--one-backend", backend]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default=DEFAULT_SIZES,
                    help="comma-separated WxHfF:N (default: %(default)s)")
    ap.add_argument("--workers", default="1,2", help="local worker counts (default 1,2)")
    ap.add_argument("--dask", action="store_true",
                    help="also run each size on a 2-worker Dask LocalCluster, check the picks")
    ap.add_argument("--json", type=Path, help="append the figures to this JSON file")
    ap.add_argument("--profile", nargs="?", const="10x10f5:1024",
                    help="profile one single-process run (default size 10x10f5:1024)")
    ap.add_argument("--top", type=int, default=40, help="rows of the --profile listing")
    ap.add_argument("--one", help=argparse.SUPPRESS)
    ap.add_argument("--one-workers", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--one-backend", default="local", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one_run(args.one, args.one_workers, args.one_backend)))
        return
    if args.profile:
        profile_run(args.profile, args.top)
        return
    rows = json.loads(args.json.read_text()) if args.json and args.json.exists() else []
    print(f"{'size':<14}{'backend':<8}{'workers':>8}{'seconds':>10}{'CPU s':>8}"
          f"{'RSS main':>10}{'RSS all':>10}{'load':>6}  picks")
    for size in args.sizes.split(","):
        runs = [(int(k), "local") for k in args.workers.split(",")]
        if args.dask:
            runs.append((2, "dask"))
        base = None
        for workers, backend in runs:
            r = _child(size, workers, backend)
            base = base or r["digest"]
            same = "same" if r["digest"] == base else "DIFFERENT"
            print(f"{size:<14}{backend:<8}{workers:>8}{r['seconds']:>10.1f}"
                  f"{r.get('cpu_seconds', float('nan')):>8.1f}"
                  f"{r['peak_rss_main_mb']:>8} MB{r['peak_rss_total_mb']:>7} MB"
                  f"{r['load_avg_1min']:>6}  {same} {r['picks'][0]}", flush=True)
            rows.append(r)
            if args.json:
                args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
