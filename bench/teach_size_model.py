"""Measure one `teach` run's time and peak memory on random domains of growing size, and fit
the model `cfteach check` uses (src/cfteach/domains/size.py).

    .venv/bin/python bench/teach_size_model.py [SPEC ...]
        (default: random:8x8:f3:n16:s0 random:12x12:f3:n64:s0 random:16x16:f3:n128:s0)

Each run is a fresh process (peak RSS = ru_maxrss). Prints N = instances x (most states + 1),
seconds, peak MB, what the current model predicts, and a least-squares fit of
log(memory - 90 MB) = log(a) + j log(N) and log(time) = log(c) + k log(N).
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

_CHILD = """
import json, resource, sys, time
from cfteach import domains
from cfteach.domains.size import estimate_size
from cfteach.teaching import teach
d = domains.load(sys.argv[1]); est = estimate_size(d)
t = time.perf_counter(); teach(d, sys.argv[2]); t = time.perf_counter() - t
print(json.dumps({"N": est.padded_states, "seconds": t,
                  "peak": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
                  "model_seconds": est.teach_seconds, "model_peak": est.teach_peak_bytes}))
"""


def main(specs: list[str]) -> None:
    rows = []
    print(f"{'domain':28} {'cond':9} {'N':>8} {'s':>7} {'model s':>8} {'MB':>7} {'model MB':>9}")
    for spec in specs:
        for cond in ("proposed",):
            out = subprocess.run([sys.executable, "-c", _CHILD, spec, cond], check=True,
                                 capture_output=True, text=True).stdout
            r = json.loads(out.strip().splitlines()[-1])
            rows.append(r)
            print(f"{spec:28} {cond:9} {r['N']:>8} {r['seconds']:7.1f} "
                  f"{r['model_seconds']:8.1f} {r['peak'] / 1e6:7.0f} "
                  f"{r['model_peak'] / 1e6:9.0f}")
    n = np.array([r["N"] for r in rows], dtype=float)
    mem = np.array([r["peak"] for r in rows])
    sec = np.array([r["seconds"] for r in rows])
    j, loga = np.polyfit(np.log(n), np.log(np.maximum(mem - 90e6, 1e6)), 1)
    k, logc = np.polyfit(np.log(n), np.log(np.maximum(sec, 1e-3)), 1)
    print(f"fit: memory = 90 MB + {np.exp(loga):.0f} B x N^{j:.2f}; "
          f"time = {np.exp(logc):.2e} s x N^{k:.2f}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["random:8x8:f3:n16:s0", "random:12x12:f3:n64:s0",
                          "random:16x16:f3:n128:s0"])
