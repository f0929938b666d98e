"""How long the report's pictures take, and raw rendering throughput.

    python bench/report_pictures.py [RESULTS_DIR]

RESULTS_DIR holds `<domain>/*.json` from `cfteach reproduce` (default: out/reproduce; if it
does not exist, the job is run there first). The report is redrawn into a temporary copy.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    src = Path(sys.argv[1] if len(sys.argv) > 1 else "out/reproduce")
    if not any(src.glob("*/*.json")):
        from cfteach.report.reproduce import reproduce

        t = time.perf_counter()
        reproduce(src, progress=False, report=False)
        print(f"teaching + tests (all domains): {time.perf_counter() - t:.1f} s")

    from cfteach import domains, render
    from cfteach.render import belief
    from cfteach.report import build_report, load_results

    results = load_results(src)
    with tempfile.TemporaryDirectory() as tmp:
        for p in src.glob("*/*.json"):
            (Path(tmp) / p.parent.name).mkdir(exist_ok=True)
            shutil.copy(p, Path(tmp) / p.parent.name / p.name)
        t = time.perf_counter()
        build_report(tmp, results, progress=False)
        total = time.perf_counter() - t
        n_files = sum(1 for _ in Path(tmp).glob("*/img/*"))
        size = sum(p.stat().st_size for p in Path(tmp).glob("*/img/*")) / 1e6
    print(f"report for {', '.join(results)}: {n_files} pictures, {size:.1f} MB, {total:.1f} s")

    inst = domains.load("tiles").instances()[-1]
    scene = render.scene_of(inst, inst.initial_state)
    for name, fn in (
        ("PNG frame (48 px cells)", lambda: render.to_image(scene, 48)),
        ("SVG document", lambda: render.to_svg(scene)),
        ("text", lambda: render.to_text(scene)),
    ):
        n, t = 0, time.perf_counter()
        while time.perf_counter() - t < 0.5:
            fn()
            n += 1
        print(f"{name}: {n / (time.perf_counter() - t):,.0f} per s")
    t = time.perf_counter()
    for _ in range(3):
        fig = belief.plot_belief_sphere(
            [[0, 0, -1], [-1, 0, 0]], w_true=[-1, -1, -1], resolution=60
        )
        belief.save_figure(fig, Path(tempfile.gettempdir()) / "bench-sphere.png")
    print(f"belief sphere (60 x 120 mesh, PNG): {(time.perf_counter() - t) / 3:.2f} s each")


if __name__ == "__main__":
    main()
