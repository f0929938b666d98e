"""Time each stage of `cfteach analyze` on simulated studies of growing size.

    .venv/bin/python bench/analysis_pipeline.py [N ...]     (default: 216 1000 3000)

Prints seconds per stage: simulate, write CSVs, load + validate, exclusions + statistics,
figures, report. The first run also pays for importing pingouin/matplotlib (shown apart).
"""

from __future__ import annotations

import sys
import tempfile
import time
import warnings
from pathlib import Path


def main(sizes: list[int]) -> None:
    t0 = time.perf_counter()
    import pingouin  # noqa: F401

    from cfteach.analysis import SyntheticConfig, generate, load_export, write_export
    from cfteach.analysis.figures import make_figures
    from cfteach.analysis.pipeline import compute_results
    from cfteach.analysis.report import write_report

    print(f"imports: {time.perf_counter() - t0:.2f} s")
    warnings.filterwarnings("ignore")
    print(
        f"{'N':>6} {'tests':>7} {'simulate':>9} {'write':>7} {'load':>7} {'stats':>7} "
        f"{'figures':>8} {'report':>7} {'total':>7}"
    )
    for n in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp)
            times = []
            t = time.perf_counter()
            ex = generate(SyntheticConfig(n_participants=n, seed=0))
            times.append(time.perf_counter() - t)
            t = time.perf_counter()
            write_export(ex, d / "export")
            times.append(time.perf_counter() - t)
            t = time.perf_counter()
            ex = load_export(d / "export")
            times.append(time.perf_counter() - t)
            t = time.perf_counter()
            results, frames = compute_results(ex)
            times.append(time.perf_counter() - t)
            t = time.perf_counter()
            figs = make_figures(frames, results, d / "out" / "figures")
            times.append(time.perf_counter() - t)
            t = time.perf_counter()
            write_report(results, figs, d / "out")
            times.append(time.perf_counter() - t)
            print(
                f"{n:>6} {len(ex.tests):>7} "
                + " ".join(f"{x:>7.2f}s" for x in times)
                + f" {sum(times):>6.2f}s"
            )


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [216, 1000, 3000])
