"""Regenerate docs/closed-loop.md's pictures from the current code: the teacher's particle
belief (delivery) before and after a wrong answer to a diagnostic test, and after the
feedback that follows it.

    .venv/bin/python scripts/closed-loop-figures.py [OUT_DIR]     # default: docs/images
"""

from __future__ import annotations

import sys
from pathlib import Path


def main(out: Path) -> list[Path]:
    from cfteach import teaching
    from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, build_pool
    from cfteach.render.belief import plot_particles_sphere, save_figure

    out.mkdir(parents=True, exist_ok=True)
    cur = teaching.teach("delivery", "proposed")
    pool = build_pool("delivery", held_out=teaching.select_tests("delivery", training=[cur]))
    dom = pool.domain
    teacher = ClosedLoopTeacher(pool, TeacherSettings(n_particles=600), seed=0)
    while (item := teacher.next()).kind != "test":
        teacher.observe({})  # the lesson was shown

    def draw(name: str, title: str) -> Path:
        b = teacher.belief
        fig = plot_particles_sphere(b.particles, b.weights, w_true=dom.weights,
                                    prior=dom.prior, feature_names=dom.feature_names,
                                    title=f"{title}\nexpected area {b.expected_area():.3f} sr")
        path = out / f"closed-loop-{name}.png"
        save_figure(fig, path)
        return path

    paths = [draw("before", "after a lesson")]
    # a wrong but finished answer: the test's first alternative that is worse than optimal
    alts = pool.test_alternatives(item.demo)
    worse = alts[alts @ dom.weights < pool.ds.mu[item.demo] @ dom.weights - 1e-9]
    teacher.observe({"feature_counts": worse[0].tolist(), "finished": True})
    paths.append(draw("wrong-answer", "after a wrong test answer"))
    assert teacher.next().kind == "feedback"
    teacher.observe({})
    paths.append(draw("feedback", "after the feedback"))
    return paths


if __name__ == "__main__":
    for p in main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/images")):
        print(p)
