"""Regenerate docs/closed-loop.md's picture from the current code: the teacher's particle
belief (delivery) after a lesson, after a wrong answer to the diagnostic test about it, and
after the feedback that follows, side by side from one viewpoint.

    .venv/bin/python scripts/closed-loop-figures.py [OUT_DIR]     # default: docs/images
"""

from __future__ import annotations

import sys
from pathlib import Path


def main(out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from cfteach import teaching
    from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, build_pool
    from cfteach.render.belief import _auto_view, plot_particles_sphere, save_figure

    out.mkdir(parents=True, exist_ok=True)
    cur = teaching.teach("delivery", "proposed")
    pool = build_pool("delivery", held_out=teaching.select_tests("delivery", training=[cur]))
    dom = pool.domain
    teacher = ClosedLoopTeacher(pool, TeacherSettings(n_particles=600), seed=0)
    while (item := teacher.next()).kind != "test":
        teacher.observe({})  # the lesson was shown
    snaps = [("after the lesson", teacher.belief.copy())]
    # a wrong but finished answer: the test's first alternative that is worse than optimal
    alts = pool.test_alternatives(item.demo)
    worse = alts[alts @ dom.weights < pool.ds.mu[item.demo] @ dom.weights - 1e-9]
    teacher.observe({"feature_counts": worse[0].tolist(), "finished": True})
    snaps.append(("after a wrong answer", teacher.belief.copy()))
    if teacher.next().kind != "feedback":
        raise RuntimeError("expected feedback after a wrong answer")
    teacher.observe({})
    snaps.append(("after the feedback", teacher.belief.copy()))

    # one viewpoint for the three panels: between w* and where the wrong answer moved the mass
    wrong = snaps[1][1]
    view = _auto_view(np.asarray(dom.weights) + wrong.weights @ wrong.particles)
    fig = plt.figure(figsize=(10.2, 4.2), dpi=100)
    for k, (title, b) in enumerate(snaps):
        ax = fig.add_subplot(1, 3, k + 1, projection="3d", computed_zorder=False)
        plot_particles_sphere(b.particles, b.weights, w_true=dom.weights, prior=dom.prior,
                              feature_names=dom.feature_names, ax=ax, view=view,
                              title=f"{title}\nexpected area {b.expected_area():.2f} sr")
    path = out / "closed-loop-belief.png"
    fig.subplots_adjust(left=0.01, right=0.99, top=0.86, bottom=0.02, wspace=0.05)
    save_figure(fig, path)
    return path


if __name__ == "__main__":
    print(main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/images")))
